// Built-in pair kernels (spec/BENCHMARKS.md): plain functors, callable on host and device.
// A method calls kernel(acc, dx, dy, dz, r2) once per in-range (target, source) pair, with
// d = x_source - x_target and r2 = squared_distance(d), and writes acc out once per target.
#pragma once

#include <cstdint>
#include <string>
#include <string_view>

#include "raycut/predicate.hpp"

namespace raycut {

enum class Kernel {
  count,   // number of in-range neighbours per target (exact integers)
  lj,      // Lennard-Jones energy per target: sum 4 eps ((sigma/r)^12 - (sigma/r)^6)
  smooth,  // w = C^2 - r^2; energy += w^2; force += w d (finite everywhere)
};

// Parse "count" / "lj" / "smooth"; throws Error(invalid_argument) naming the bad value.
Kernel parse_kernel(std::string_view name);
std::string to_string(Kernel kernel);

struct KernelOptions {
  float lj_epsilon = 1.0f;  // the paper's values
  float lj_sigma = 1.0f;
};

// What one target accumulates; each kernel touches only the fields it produces.
struct Accumulator {
  std::uint32_t count = 0;
  float energy = 0.0f;
  float fx = 0.0f, fy = 0.0f, fz = 0.0f;
};

struct CountKernel {
  static constexpr bool has_count = true, has_energy = false, has_force = false;
  RAYCUT_HD void operator()(Accumulator& acc, float, float, float, float) const { ++acc.count; }
};

struct LennardJonesKernel {
  static constexpr bool has_count = false, has_energy = true, has_force = false;
  float four_epsilon;
  float sigma_squared;
  RAYCUT_HD void operator()(Accumulator& acc, float, float, float, float r2) const {
    const float s2 = sigma_squared / r2;
    const float s6 = s2 * s2 * s2;
    acc.energy += four_epsilon * (s6 * s6 - s6);
  }
};

struct SmoothKernel {
  static constexpr bool has_count = false, has_energy = true, has_force = true;
  float cutoff_squared;
  RAYCUT_HD void operator()(Accumulator& acc, float dx, float dy, float dz, float r2) const {
    const float w = cutoff_squared - r2;
    acc.energy += w * w;
    acc.fx += w * dx;
    acc.fy += w * dy;
    acc.fz += w * dz;
  }
};

// Calls f(kernel_functor) with the functor for `kernel`: one switch, shared by every method.
template <class F>
RAYCUT_HD void with_kernel(Kernel kernel, const KernelOptions& options, float cutoff_squared,
                           F&& f) {
  switch (kernel) {
    case Kernel::count:
      f(CountKernel{});
      break;
    case Kernel::lj:
      f(LennardJonesKernel{4.0f * options.lj_epsilon, options.lj_sigma * options.lj_sigma});
      break;
    case Kernel::smooth:
      f(SmoothKernel{cutoff_squared});
      break;
  }
}

}  // namespace raycut
