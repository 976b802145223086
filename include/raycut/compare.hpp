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

}  // namespace raycut
