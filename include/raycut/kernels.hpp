// Built-in pair kernels: plain functors, callable on host and device. A method calls
// kernel(acc, i, j, dx, dy, dz, r2) once per in-range (target i, source j) pair, i and j the
// caller's particle indices, d = x_j - x_i and r2 = squared_distance(d), and writes acc out once
// per target.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>

#include "raycut/error.hpp"
#include "raycut/predicate.hpp"

namespace raycut {

enum class Kernel {
  count,        // number of in-range neighbours per target (exact integers)
  lj,           // Lennard-Jones energy per target: sum 4 eps ((sigma/r)^12 - (sigma/r)^6)
  smooth,       // w = C^2 - r^2; energy += w^2; force += w d (finite everywhere)
  sph_density,  // energy = sum_{j != i} m W_poly6(r, h), h = the cutoff (self not included)
  sph_force,    // force = pressure + viscosity force of Mueller et al. 2003 (not divided by rho_i)
};

// Parse "count" / "lj" / "smooth" / "sph_density" / "sph_force"; throws Error(invalid_argument).
Kernel parse_kernel(std::string_view name);
std::string to_string(Kernel kernel);

// Per-particle inputs of sph_force, indexed by the caller's particle index, in the memory space
// of the method (Engine::space()): velocity (3 per particle), density and pressure.
struct SphInputs {
  const float* velocity = nullptr;
  const float* density = nullptr;
  const float* pressure = nullptr;
};

struct KernelOptions {
  float lj_epsilon = 1.0f;  // the paper's values
  float lj_sigma = 1.0f;
  float sph_mass = 0.0f;       // particle mass m
  float sph_viscosity = 0.0f;  // mu
  SphInputs sph;
};

// What one target accumulates; each kernel touches only the fields it produces.
struct Accumulator {
  std::uint32_t count = 0;
  float energy = 0.0f;
  float fx = 0.0f, fy = 0.0f, fz = 0.0f;
};

// 1 / b: on the device the hardware reciprocal (within 1 ulp; the IEEE division costs as much as
// the rest of a Lennard-Jones pair), flushing denormal b to 0 (1 / b overflows either way):
// 1.0f / b compiles to a fix-up of denormals that costs 3 more instructions per pair. On the
// host the division.
RAYCUT_HD float fast_reciprocal(float b) {
#if defined(__CUDA_ARCH__)
  float r;
  asm("rcp.approx.ftz.f32 %0, %1;" : "=f"(r) : "f"(b));
  return r;
#else
  return 1.0f / b;
#endif
}

// A kernel adds each pair's terms to the target's Accumulator; finish() then applies, once per
// target, the constant factors common to all its terms (an instruction less per pair in the
// hottest loop). The geometric kernels ignore the indices.
struct CountKernel {
  static constexpr bool has_count = true, has_energy = false, has_force = false;
  static constexpr bool vanishes_at_infinity = false;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, std::uint32_t, float, float, float,
                            float) const {
    ++acc.count;
  }
  RAYCUT_HD void finish(Accumulator&) const {}
};

// 4 eps ((sigma/r)^12 - (sigma/r)^6) = 4 eps sigma^6 * w (sigma^6 w - 1) with w = r^-6: per pair
// a reciprocal, two products and two fused operations; 4 eps sigma^6 once per target. Its terms
// vanish at r2 = +inf (w = 0), so a pair out of range can be fed r2 = +inf instead of a branch.
struct LennardJonesKernel {
  static constexpr bool has_count = false, has_energy = true, has_force = false;
  static constexpr bool vanishes_at_infinity = true;
  float sigma6;               // sigma^6
  float four_epsilon_sigma6;  // 4 eps sigma^6
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, std::uint32_t, float, float, float,
                            float r2) const {
    const float t = fast_reciprocal(r2);
    const float w = t * t * t;
    acc.energy += w * (sigma6 * w - 1.0f);
  }
  RAYCUT_HD void finish(Accumulator& acc) const { acc.energy *= four_epsilon_sigma6; }
};

struct SmoothKernel {
  static constexpr bool has_count = false, has_energy = true, has_force = true;
  static constexpr bool vanishes_at_infinity = false;
  float cutoff_squared;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, std::uint32_t, float dx, float dy,
                            float dz, float r2) const {
    const float w = cutoff_squared - r2;
    acc.energy += w * w;
    acc.fx += w * dx;
    acc.fy += w * dy;
    acc.fz += w * dz;
  }
  RAYCUT_HD void finish(Accumulator&) const {}
};

// rho_i contribution m W_poly6(r, h) = m 315 / (64 pi h^9) (h^2 - r^2)^3 (Mueller et al. 2003).
struct SphDensityKernel {
  static constexpr bool has_count = false, has_energy = true, has_force = false;
  static constexpr bool vanishes_at_infinity = false;
  float mass_poly6;  // m 315 / (64 pi h^9)
  float h_squared;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, std::uint32_t, float, float, float,
                            float r2) const {
    const float w = h_squared - r2;
    acc.energy += w * w * w;
  }
  RAYCUT_HD void finish(Accumulator& acc) const { acc.energy *= mass_poly6; }
};

// f_i = - sum_j m (p_i + p_j) / (2 rho_j) grad W_spiky + mu sum_j m (v_j - v_i) / rho_j lap W_visc
// with grad W_spiky = 45 / (pi h^6) (h - r)^2 d / r pointing from i to j (so positive pressure
// pushes i away from j) and lap W_visc = 45 / (pi h^6) (h - r). Coincident pairs (r = 0) have no
// direction and get no pressure force.
struct SphForceKernel {
  static constexpr bool has_count = false, has_energy = false, has_force = true;
  static constexpr bool vanishes_at_infinity = false;
  float mass, h, spiky;  // spiky = 45 / (pi h^6)
  float viscosity;
  SphInputs in;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t i, std::uint32_t j, float dx, float dy,
                            float dz, float r2) const {
    const float r = sqrtf(r2);
    const float h_r = h - r;
    const float rho_j = in.density[j];
    if (r2 > 0.0f) {
      const float pressure =
          -mass * (in.pressure[i] + in.pressure[j]) / (2.0f * rho_j) * spiky * h_r * h_r / r;
      acc.fx += pressure * dx;
      acc.fy += pressure * dy;
      acc.fz += pressure * dz;
    }
    const float visc = viscosity * mass / rho_j * spiky * h_r;
    acc.fx += visc * (in.velocity[3 * j] - in.velocity[3 * i]);
    acc.fy += visc * (in.velocity[3 * j + 1] - in.velocity[3 * i + 1]);
    acc.fz += visc * (in.velocity[3 * j + 2] - in.velocity[3 * i + 2]);
  }
  RAYCUT_HD void finish(Accumulator&) const {}
};

// Which per-target outputs a kernel produces (without building its functor).
struct KernelOutputs {
  bool count, energy, force;
};
constexpr KernelOutputs outputs_of(Kernel kernel) {
  switch (kernel) {
    case Kernel::count:
      return {true, false, false};
    case Kernel::lj:
    case Kernel::sph_density:
      return {false, true, false};
    case Kernel::smooth:
      return {false, true, true};
    case Kernel::sph_force:
      return {false, false, true};
  }
  return {false, false, false};
}

// Calls f(kernel_functor) with the functor for `kernel`: one switch, shared by every method.
template <class F>
void with_kernel(Kernel kernel, const KernelOptions& options, float cutoff_squared, F&& f) {
  constexpr float pi = 3.14159265358979f;
  const float h = std::sqrt(cutoff_squared);
  switch (kernel) {
    case Kernel::count:
      f(CountKernel{});
      break;
    case Kernel::lj: {
      const float sigma2 = options.lj_sigma * options.lj_sigma, sigma6 = sigma2 * sigma2 * sigma2;
      f(LennardJonesKernel{sigma6, 4.0f * options.lj_epsilon * sigma6});
      break;
    }
    case Kernel::smooth:
      f(SmoothKernel{cutoff_squared});
      break;
    case Kernel::sph_density: {
      const double h3 = static_cast<double>(h) * h * h;
      f(SphDensityKernel{static_cast<float>(options.sph_mass * 315.0 / (64.0 * pi * h3 * h3 * h3)),
                         cutoff_squared});
      break;
    }
    case Kernel::sph_force: {
      if (!options.sph.velocity || !options.sph.density || !options.sph.pressure)
        throw Error(ErrorCode::invalid_argument,
                    "sph_force needs velocity, density and pressure inputs (KernelOptions::sph)");
      const double h3 = static_cast<double>(h) * h * h;
      f(SphForceKernel{options.sph_mass, h, static_cast<float>(45.0 / (pi * h3 * h3)),
                       options.sph_viscosity, options.sph});
      break;
    }
  }
}

}  // namespace raycut
