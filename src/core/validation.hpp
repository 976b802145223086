// Input checks done before any device work (spec/METHODS.md, contract 4).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>

#include "raycut/engine.hpp"

namespace raycut::detail {

// Throws Error(invalid_argument) unless the cutoff is finite and > 0.
void validate_cutoff(float cutoff);

// Index of the first particle with a non-finite coordinate in host memory, or n if none.
std::size_t first_non_finite_host(const float* xyz, std::size_t n);

// Throws Error(invalid_input) naming particle `index` and its coordinates.
[[noreturn]] void throw_non_finite(std::size_t index, const float* xyz_of_index);

// Sizes list.indices for `pairs` entries; throws Error(out_of_memory) saying how much a list
// that does not fit in host memory would need, instead of std::bad_alloc.
void allocate_indices(NeighbourList& list, std::uint64_t pairs);

// "1.50 GiB", "12.0 MiB": for memory messages.
std::string format_bytes(double bytes);

}  // namespace raycut::detail
