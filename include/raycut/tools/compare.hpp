// Comparing a method's answer with an oracle's: the one implementation behind `raycut check`
// and the conformance tests.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "raycut/engine.hpp"

namespace raycut {

struct NeighbourComparison {
  std::size_t targets = 0;            // N
  std::size_t differing_targets = 0;  // targets whose neighbour multiset differs
  std::uint64_t pairs = 0;            // entries in the list compared
  std::uint64_t expected_pairs = 0;   // entries in the oracle's list
  std::string first_difference;       // "target i: ...; missing ...; extra ..." or empty
  bool equal() const { return differing_targets == 0 && first_difference.empty(); }
};

// Per-target comparison as multisets (order within a row ignored; a duplicate is a difference).
// When `expected` has shifts (ListOptions::shifts), an entry is (j, S): the same source through
// another image is a different entry, and `got` must have its shifts too.
NeighbourComparison compare_neighbours(const NeighbourList& got, const NeighbourList& expected);

// |got - want| / scale, NaN-aware, for comparing kernel results: +inf (a failure at every
// tolerance) when either value is NaN, when exactly one is infinite, or when they are infinities
// of opposite signs; 0 when both are the same infinity. So a NaN is never swallowed by a max()
// and an overflow on one side only is a mismatch.
double scaled_difference(double got, double want, double scale);

// The largest scaled_difference(got[k], want[k], scale[k / stride]) over all k (stride: values
// per scale, e.g. 3 for forces with one scale per target); +inf when the sizes differ, 0 when
// both are empty.
double max_scaled_difference(const std::vector<float>& got, const std::vector<float>& want,
                             const std::vector<double>& scale, std::size_t stride = 1);

// The smooth kernel (include/raycut/kernels.hpp: w = C^2 - r^2, energy += w^2, force += w r)
// summed in double over a list's entries (r = x_j - x_i + S . cell, S from the list's shifts in
// a box), and per target the error a float evaluation of the same terms may have:
//   bound = 2 ((n + 1) u sum|t| + n e_t),  u = 2^-24, n the target's terms,
// the first part the worst case of a float sum of n terms in any order, e_t the error of one
// float term (13 u C^4 for the energy, 9 u C^3 for the force, plus what r's rounding at the box's
// scale adds in a periodic box), doubled to spare. A tolerance a check can defend: it grows
// with the number and the size of the terms, not with the magnitude of the positions.
struct SmoothReference {
  std::vector<double> energy, force;              // per target (force: 3 per target)
  std::vector<double> energy_bound, force_bound;  // per target
};
SmoothReference smooth_reference(const float* xyz, float cutoff, const NeighbourList& list,
                                 const Box& box = Box::open());

// The largest |got - reference| / bound over every energy and force value: <= 1 passes. +inf
// when a value is NaN, non-finite on one side only, or the sizes differ (scaled_difference).
double smooth_bound_ratio(const Results& got, const SmoothReference& reference);

}  // namespace raycut
