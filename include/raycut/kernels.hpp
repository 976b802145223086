// Pair functors: what a method runs for every in-range (target i, source j) pair, fused in its
// own traversal. The built-in kernels below are ordinary functors; a user's own follows the same
// contract (include/raycut/functor.hpp: its shape, its options, the compile-time checks;
// include/raycut/pairs.hpp runs one on the CPU methods, include/raycut/cuda/pairs.cuh on the CUDA
// methods).
//
// i and j are the caller's particle indices (with query points: i a query, j a source); with a
// periodic box r already includes the image shift (r = x_j - x_i + S . cell). The functor carries
// its outputs (pointers it writes in finish) and its parameters; it is copied to the device by
// value, so it holds no host-only state when run on a GPU method.
#pragma once

#include <cmath>
#include <cstdint>
#include <string>
#include <string_view>
#include <type_traits>

#include "raycut/error.hpp"
#include "raycut/functor.hpp"
#include "raycut/predicate.hpp"

namespace raycut {

enum class Kernel {
  count,        // number of in-range neighbours per target (exact integers)
  lj,           // Lennard-Jones energy per target: sum_j 4 eps ((sigma/r)^12 - (sigma/r)^6),
                // every pair counted fully on both sides (the paper's kernel: sum = 2 E)
  lj_forces,    // Lennard-Jones energy, force and virial per target, in one pass; energy and
                // virial shared half and half between the pair's atoms (sum = the system's)
  smooth,       // w = C^2 - r^2; energy += w^2; force += w d (finite everywhere)
  sph_density,  // density = sum_{j != i} m W_poly6(r, h), h = the cutoff (self not included)
  sph_force,    // force = pressure + viscosity force of Mueller et al. 2003 (not divided by rho_i)
};

// Parse "count" / "lj" / "lj_forces" / "smooth" / "sph_density" / "sph_force"; throws
// Error(invalid_argument).
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
  // lj_forces only: the pair energy shifted to 0 at the cutoff C, 4 eps [u(r) - u(C)] with
  // u = (sigma/r)^12 - (sigma/r)^6, as ASE's LennardJones (smooth=False) and LAMMPS's
  // pair_modify shift yes. Forces and virial do not change. `lj` (the paper's kernel) refuses it.
  bool lj_shift = false;
  float sph_mass = 0.0f;       // particle mass m
  float sph_viscosity = 0.0f;  // mu
  SphInputs sph;
};

// Throws Error(invalid_argument), naming the kernel, the cutoff and why, when `kernel` cannot be
// evaluated in float at this cutoff (and these options) without overflow or underflow of its
// largest single-pair term: smooth (energy C^4, force C^3), sph_density (the factor
// m 315 / (64 pi h^9) and the raw term h^6), sph_force (the factor 45 / (pi h^6) and the terms
// m 45 / (pi h^6) h^2 (pressure, per unit p / rho) and mu m 45 / (pi h^6) h (viscosity, per unit
// v / rho)), lj (4 eps sigma^6 and sigma^6; no cutoff-dependent bound: its growth as r -> 0 is
// the physics). count never throws. Everything is evaluated in double from the formulas of
// include/raycut/kernels.hpp. Engine::run calls it before any work (docs/limits.md).
void validate_kernel_range(Kernel kernel, const KernelOptions& options, float cutoff);

// Where the built-in kernels write, per target (the caller's index); null where not produced.
struct KernelOutputs {
  std::uint32_t* count = nullptr;  // 1 per target
  float* energy = nullptr;         // 1 per target
  float* force = nullptr;          // 3 per target: fx fy fz
  float* virial = nullptr;         // 6 per target: xx yy zz xy xz yz
  float* density = nullptr;        // 1 per target
};

// Which of KernelOutputs a built-in kernel writes.
struct KernelProduces {
  bool count = false, energy = false, force = false, virial = false, density = false;
};
constexpr KernelProduces produces(Kernel kernel) {
  switch (kernel) {
    case Kernel::count:
      return {true, false, false, false, false};
    case Kernel::lj:
      return {false, true, false, false, false};
    case Kernel::lj_forces:
      return {false, true, true, true, false};
    case Kernel::smooth:
      return {false, true, true, false, false};
    case Kernel::sph_density:
      return {false, false, false, false, true};
    case Kernel::sph_force:
      return {false, false, true, false, false};
  }
  return {};
}

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

// ---- built-in kernels ------------------------------------------------------------------------
// Each adds a pair's terms to its Accumulator; finish() then applies, once per target, the
// constant factors common to all terms (an instruction less per pair in the hottest loop).

struct CountKernel {
  using Accumulator = std::uint32_t;
  using options = functor_options<option::combine>;
  std::uint32_t* count;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, Vec3, float) const { ++acc; }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const { count[i] = acc; }
};

// The paper's Lennard-Jones kernel: per target, the sum over its neighbours of the full pair energy
// (every pair counted on both atoms: sum_i energy_i = 2 E; lj_forces shares it half and half).
// 4 eps ((sigma/r)^12 - (sigma/r)^6) = 4 eps sigma^6 * w (sigma^6 w - 1) with w = r^-6: per pair
// a reciprocal, two products and two fused operations; 4 eps sigma^6 once per target. Its terms
// vanish at r2 = +inf (w = 0), so a pair out of range can be fed r2 = +inf instead of a branch.
struct LennardJonesKernel {
  using Accumulator = float;
  using options = functor_options<option::vanishes_at_infinity, option::combine>;
  float sigma6;               // sigma^6
  float four_epsilon_sigma6;  // 4 eps sigma^6
  float* energy;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, Vec3, float r2) const {
    const float t = fast_reciprocal(r2);
    const float w = t * t * t;
    acc += w * (sigma6 * w - 1.0f);
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const {
    energy[i] = acc * four_epsilon_sigma6;
  }
};

// Energy, force and virial of Lennard-Jones in one pass, in reduced units: with t = 1/r^2 and
// u = (sigma^2 t)^3 = (sigma/r)^6,
//   energy_i = 1/2 4 eps sum_j [u (u - 1) - shift]             (each pair half on each atom)
//   force_i  = -dU/dx_i = -24 eps sum_j t u (2 u - 1) r_ij      (r_ij = x_j - x_i)
//   virial_i = -1/2 sum_j r_ij (x) force_i(j) = 12 eps sum_j t u (2 u - 1) r r
// so that sum_i energy_i is the system's energy sum_{i<j} U(r_ij) and sum_i virial_i the system's
// virial sum_{i<j} (x_i - x_j) (x) f_ij: LAMMPS's and ASE's per-atom convention (the stress is
// -virial / volume; the virial is positive under compression). Components xx yy zz xy xz yz.
// shift = u_C (u_C - 1) at the cutoff (KernelOptions::lj_shift), 0 otherwise. Vanishes at
// r2 = +inf (u = 0 takes no shift). Unlike `lj`, whose per-target energy counts every pair fully
// (the paper's definition, kept for its benchmark), sum_i energy_i = E here.
// Reduced, because the raw force factor t w = r^-8 leaves float at every accepted sigma below
// ~1e-5 or above ~3e5 (inf, or zero forces), where u stays near 1 around the minimum and t
// scales as 1 / sigma^2 (docs/limits.md).
struct LennardJonesForceKernel {
  struct Accumulator {
    float energy = 0, f[3] = {0, 0, 0}, v[6] = {0, 0, 0, 0, 0, 0};
  };
  using options = functor_options<option::vanishes_at_infinity, option::combine>;
  float sigma2;        // sigma^2
  float four_epsilon;  // 4 eps
  float* energy;       // 1 per target
  float* force;        // 3 per target
  float* virial;       // 6 per target
  float shift = 0.0f;  // u_C (u_C - 1), reduced (0: no shift)
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, Vec3 r, float r2) const {
    const float t = fast_reciprocal(r2);
    const float s = sigma2 * t;
    const float u = s * s * s;
    acc.energy += u * (u - 1.0f);
    acc.energy -= u > 0.0f ? shift : 0.0f;      // a separate step: without a shift, the same bits
    const float g = t * u * (2.0f * u - 1.0f);  // force factor, times -6 (4 eps)
    const float gx = g * r.x, gy = g * r.y, gz = g * r.z;
    acc.f[0] += gx;
    acc.f[1] += gy;
    acc.f[2] += gz;
    acc.v[0] += gx * r.x;
    acc.v[1] += gy * r.y;
    acc.v[2] += gz * r.z;
    acc.v[3] += gx * r.y;
    acc.v[4] += gx * r.z;
    acc.v[5] += gy * r.z;
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) {
    a.energy += b.energy;
    for (int k = 0; k < 3; ++k) a.f[k] += b.f[k];
    for (int k = 0; k < 6; ++k) a.v[k] += b.v[k];
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const {
    energy[i] = acc.energy * (0.5f * four_epsilon);  // half of each pair's energy
    const float fs = -6.0f * four_epsilon, vs = 3.0f * four_epsilon;
    for (int k = 0; k < 3; ++k) force[3 * std::size_t{i} + k] = fs * acc.f[k];
    for (int k = 0; k < 6; ++k) virial[6 * std::size_t{i} + k] = vs * acc.v[k];
  }
};

// w = C^2 - r^2; energy += w^2; force += w d.
struct SmoothKernel {
  struct Accumulator {
    float energy = 0, f[3] = {0, 0, 0};
  };
  using options = functor_options<option::combine>;
  float cutoff_squared;
  float* energy;
  float* force;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, Vec3 r, float r2) const {
    const float w = cutoff_squared - r2;
    acc.energy += w * w;
    acc.f[0] += w * r.x;
    acc.f[1] += w * r.y;
    acc.f[2] += w * r.z;
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) {
    a.energy += b.energy;
    for (int k = 0; k < 3; ++k) a.f[k] += b.f[k];
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const {
    energy[i] = acc.energy;
    for (int k = 0; k < 3; ++k) force[3 * std::size_t{i} + k] = acc.f[k];
  }
};

// rho_i contribution m W_poly6(r, h) = m 315 / (64 pi h^9) (h^2 - r^2)^3 (Mueller et al. 2003).
struct SphDensityKernel {
  using Accumulator = float;
  using options = functor_options<option::combine>;
  float mass_poly6;  // m 315 / (64 pi h^9)
  float h_squared;
  float* density;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, Vec3, float r2) const {
    const float w = h_squared - r2;
    acc += w * w * w;
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const { density[i] = acc * mass_poly6; }
};

// f_i = - sum_j m (p_i + p_j) / (2 rho_j) grad W_spiky + mu sum_j m (v_j - v_i) / rho_j lap W_visc
// with grad W_spiky = 45 / (pi h^6) (h - r)^2 d / r pointing from i to j (so positive pressure
// pushes i away from j) and lap W_visc = 45 / (pi h^6) (h - r). Coincident pairs (r = 0) have no
// direction and get no pressure force.
struct SphForceKernel {
  struct Accumulator {
    float f[3] = {0, 0, 0};
  };
  using options = functor_options<option::combine>;
  float mass, h, spiky;  // spiky = 45 / (pi h^6)
  float viscosity;
  SphInputs in;
  float* force;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t i, std::uint32_t j, Vec3 r,
                            float r2) const {
    const float d = sqrtf(r2);
    const float h_r = h - d;
    const float rho_j = in.density[j];
    if (r2 > 0.0f) {
      const float pressure =
          -mass * (in.pressure[i] + in.pressure[j]) / (2.0f * rho_j) * spiky * h_r * h_r / d;
      acc.f[0] += pressure * r.x;
      acc.f[1] += pressure * r.y;
      acc.f[2] += pressure * r.z;
    }
    const float visc = viscosity * mass / rho_j * spiky * h_r;
    for (int k = 0; k < 3; ++k)
      acc.f[k] +=
          visc * (in.velocity[3 * std::size_t{j} + k] - in.velocity[3 * std::size_t{i} + k]);
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) {
    for (int k = 0; k < 3; ++k) a.f[k] += b.f[k];
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const {
    for (int k = 0; k < 3; ++k) force[3 * std::size_t{i} + k] = acc.f[k];
  }
};

// Calls f(functor) with the built-in functor for `kernel`, writing to `out`: one switch, shared
// by every method. Throws Error(invalid_argument) when `out` lacks what the kernel writes.
template <class F>
void with_kernel(Kernel kernel, const KernelOptions& options, float cutoff_squared,
                 const KernelOutputs& out, F&& f) {
  constexpr float pi = 3.14159265358979f;  // as every earlier result was computed
  const float h = std::sqrt(cutoff_squared);
  const KernelProduces p = produces(kernel);
  if ((p.count && !out.count) || (p.energy && !out.energy) || (p.force && !out.force) ||
      (p.virial && !out.virial) || (p.density && !out.density))
    throw Error(ErrorCode::invalid_argument,
                "kernel " + to_string(kernel) + ": an output it writes has a null pointer");
  const float sigma2 = options.lj_sigma * options.lj_sigma, sigma6 = sigma2 * sigma2 * sigma2;
  const double h3 = static_cast<double>(h) * h * h;
  switch (kernel) {
    case Kernel::count:
      f(CountKernel{out.count});
      break;
    case Kernel::lj:
      if (options.lj_shift)
        throw Error(ErrorCode::invalid_argument,
                    "kernel lj: lj_shift is not accepted (lj is the paper's per-target energy, "
                    "unshifted); use lj_forces for a shifted energy");
      f(LennardJonesKernel{sigma6, 4.0f * options.lj_epsilon * sigma6, out.energy});
      break;
    case Kernel::lj_forces: {
      // u_C (u_C - 1) in double, u_C = (sigma^2 / C^2)^3.
      const double reduced = static_cast<double>(sigma2) / cutoff_squared;
      const double u_cut = reduced * reduced * reduced;
      const float shift = options.lj_shift ? static_cast<float>(u_cut * (u_cut - 1.0)) : 0.0f;
      f(LennardJonesForceKernel{sigma2, 4.0f * options.lj_epsilon, out.energy, out.force,
                                out.virial, shift});
      break;
    }
    case Kernel::smooth:
      f(SmoothKernel{cutoff_squared, out.energy, out.force});
      break;
    case Kernel::sph_density:
      f(SphDensityKernel{static_cast<float>(options.sph_mass * 315.0 / (64.0 * pi * h3 * h3 * h3)),
                         cutoff_squared, out.density});
      break;
    case Kernel::sph_force:
      if (!options.sph.velocity || !options.sph.density || !options.sph.pressure)
        throw Error(ErrorCode::invalid_argument,
                    "sph_force needs velocity, density and pressure inputs (KernelOptions::sph)");
      f(SphForceKernel{options.sph_mass, h, static_cast<float>(45.0 / (pi * h3 * h3)),
                       options.sph_viscosity, options.sph, out.force});
      break;
  }
}

}  // namespace raycut
