// Input checks done before any device work (docs/limits.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "raycut/engine.hpp"

namespace raycut::detail {

// The cutoffs raycut supports: [2^-60, 2^60] (about [8.7e-19, 1.2e18]). Inside it C*C is a
// normal float with 6 binades to spare on either side, so the shared float predicate
// fma(dz, dz, fma(dy, dy, dx * dx)) < C*C agrees with the real-number answer for every pair
// whose distance is not within ~3e-7 relative of C (docs/limits.md gives the argument).
inline constexpr float min_cutoff = 0x1p-60f;
inline constexpr float max_cutoff = 0x1p60f;

// Throws Error(invalid_argument) unless the cutoff is finite and in [min_cutoff, max_cutoff];
// the message names the supported range.
void validate_cutoff(float cutoff);
// The same check on a cutoff given in double, before it is rounded to float.
void validate_cutoff_value(double cutoff);

// Throws Error(invalid_argument) unless `cutoffs` (ListOptions::cutoffs) fits n particles: radii
// or species with a symmetric kinds x kinds table, not both; species below kinds; each value
// finite and >= 0; every pair's cutoff at most `search` (the engine's cutoff: 2 max r_i for
// radii, since a particle pairs with its own images). Names the value and what is accepted.
void validate_pair_cutoffs(const PairCutoffs& cutoffs, std::size_t n, double search);

// Index of the first particle with a non-finite coordinate in host memory, or n if none.
std::size_t first_non_finite_host(const float* xyz, std::size_t n);

// Throws Error(invalid_input) naming particle `index` and its coordinates.
// `what`: which points, "particle" (the sources) or "query point".
[[noreturn]] void throw_non_finite(std::size_t index, const float* xyz_of_index,
                                   const char* what = "particle");

// Sizes list.indices for `pairs` entries; throws Error(out_of_memory) saying how much a list
// that does not fit in host memory would need, instead of std::bad_alloc.
void allocate_indices(NeighbourList& list, std::uint64_t pairs);

// A value in messages: three significant digits.
std::string number(double value);

// "1.50 GiB", "12.0 MiB": for memory messages.
std::string format_bytes(double bytes);

}  // namespace raycut::detail
