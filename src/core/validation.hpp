// Input checks done before any device work (spec/METHODS.md, contract 4).
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

// Throws Error(invalid_argument), naming the kernel, the cutoff and why, when `kernel` cannot be
// evaluated in float at this cutoff (and these options) without overflow or underflow of its
// largest single-pair term: smooth (energy C^4, force C^3), sph_density (the factor
// m 315 / (64 pi h^9) and the raw term h^6), sph_force (the factor 45 / (pi h^6) and the terms
// m 45 / (pi h^6) h^2 (pressure, per unit p / rho) and mu m 45 / (pi h^6) h (viscosity, per unit
// v / rho)), lj (4 eps sigma^6 and sigma^6; no cutoff-dependent bound: its growth as r -> 0 is
// the physics). count never throws. Everything is evaluated in double from the formulas of
// include/raycut/kernels.hpp. For Engine::run to call before any work.
void validate_kernel_range(Kernel kernel, const KernelOptions& options, float cutoff);

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
