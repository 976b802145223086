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

#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <string>
#include <string_view>
#include <type_traits>

#include "raycut/error.hpp"
#include "raycut/functor.hpp"
#include "raycut/predicate.hpp"

namespace raycut {

// The built-in kernels, in the order of BuiltinKernels (below): each value names one entry of
// that catalogue, which says everything else about it (name, parameters, inputs, outputs).
enum class Kernel {
  count,        // number of in-range neighbours per target (exact integers)
  lj,           // Lennard-Jones energy per target: sum_j 4 eps ((sigma/r)^12 - (sigma/r)^6),
                // every pair counted fully on both sides (the paper's kernel: sum = 2 E)
  lj_forces,    // Lennard-Jones energy, force and virial per target, in one pass; energy and
                // virial shared half and half between the pair's atoms (sum = the system's)
  smooth,       // w = C^2 - r^2; energy += w^2; force += w d (finite everywhere)
  sph_density,  // density = sum_{j != i} m W_poly6(r, h), h = the cutoff (self not included)
  sph_force,    // force = pressure + viscosity force of Mueller et al. 2003 (not divided by rho_i)
  coulomb_dsf,  // damped shifted-force Coulomb (Fennell & Gezelter 2006): energy, force, virial
};

// Parse a kernel's name ("count", "lj", "lj_forces", ...: kernel_catalogue_names()); throws
// Error(invalid_argument) naming the known ones.
Kernel parse_kernel(std::string_view name);
std::string to_string(Kernel kernel);

// Per-particle inputs of sph_force, indexed by the caller's particle index, in the memory space
// of the method (Engine::space()): velocity (3 per particle), density and pressure.
struct SphInputs {
  const float* velocity = nullptr;
  const float* density = nullptr;
  const float* pressure = nullptr;
};

// Per-particle input of coulomb_dsf, in the memory space of the method: the charge of every
// source (indexed by the caller's particle index j) and, with query points only, the charge of
// every query (indexed by the query's index; without query points the targets are the sources
// and `charge` serves both ends).
struct CoulombInputs {
  const float* charge = nullptr;
  const float* query_charge = nullptr;
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
  float dsf_alpha = 0.0f;         // coulomb_dsf: damping alpha (1 / length), >= 0
  float coulomb_constant = 1.0f;  // coulomb_dsf: k of k q_i q_j / r (e.g. 14.399645 eV A / e^2)
  CoulombInputs coulomb;
};

// Throws Error(invalid_argument), naming the kernel, the cutoff and why, when `kernel` cannot be
// evaluated in float at this cutoff (and these options) without overflow or underflow of its
// largest single-pair term: smooth (energy C^4, force C^3), sph_density (the factor
// m 315 / (64 pi h^9) and the raw term h^6), sph_force (the factor 45 / (pi h^6) and the terms
// m 45 / (pi h^6) h^2 (pressure, per unit p / rho) and mu m 45 / (pi h^6) h (viscosity, per unit
// v / rho)), lj (4 eps sigma^6 and sigma^6; no cutoff-dependent bound: its growth as r -> 0 is
// the physics), coulomb_dsf (alpha C, k, and the shift constants erfc(alpha C) / C and
// erfc(alpha C) / C^2 + 2 alpha / sqrt(pi) exp(-alpha^2 C^2) / C). Then every float parameter
// the kernel reads must be finite and within its catalogue range (KernelParameter). count never
// throws. Everything is evaluated in double from the formulas of
// include/raycut/kernels.hpp. Engine::run calls it before any work (docs/limits.md).
void validate_kernel_range(Kernel kernel, const KernelOptions& options, float cutoff);

// Throws Error naming the kernel and the input when the per-particle inputs of `options` do not
// fit a run of `kernel` with (or without) query points: a kernel that reads its inputs at both
// ends of a pair from one array refuses query points (unsupported); an input it needs is null,
// or a query-side input is given without query points (invalid_argument).
void validate_kernel_inputs(Kernel kernel, const KernelOptions& options, bool query_points);

// Where the built-in kernels write, per target (the caller's index); null where not produced.
struct KernelOutputs {
  std::uint32_t* count = nullptr;  // 1 per target
  float* energy = nullptr;         // 1 per target
  float* force = nullptr;          // 3 per target: fx fy fz
  float* virial = nullptr;         // 6 per target: xx yy zz xy xz yz
  float* density = nullptr;        // 1 per target
};

// Which of KernelOutputs a built-in kernel writes (produces(kernel), from the catalogue below).
struct KernelProduces {
  bool count = false, energy = false, force = false, virial = false, density = false;
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

// ---- built-in kernels ------------------------------------------------------------------------
// Each adds a pair's terms to its Accumulator; finish() then applies, once per target, the
// constant factors common to all terms (an instruction less per pair in the hottest loop).

struct CountKernel {
  using Accumulator = std::uint32_t;
  using options = functor_options<option::combine, option::repeatable, option::mirror>;
  std::uint32_t* count;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, Vec3, float) const { ++acc; }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  RAYCUT_HD static void mirror(Accumulator&) {}
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const { count[i] = acc; }
};

// The paper's Lennard-Jones kernel: per target, the sum over its neighbours of the full pair energy
// (every pair counted on both atoms: sum_i energy_i = 2 E; lj_forces shares it half and half).
// 4 eps ((sigma/r)^12 - (sigma/r)^6) = 4 eps sigma^6 * w (sigma^6 w - 1) with w = r^-6: per pair
// a reciprocal, two products and two fused operations; 4 eps sigma^6 once per target. Its terms
// vanish at r2 = +inf (w = 0), so a pair out of range can be fed r2 = +inf instead of a branch.
struct LennardJonesKernel {
  using Accumulator = float;
  using options = functor_options<option::vanishes_at_infinity, option::combine, option::repeatable,
                                  option::mirror>;
  float sigma6;               // sigma^6
  float four_epsilon_sigma6;  // 4 eps sigma^6
  float* energy;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, Vec3, float r2) const {
    const float t = fast_reciprocal(r2);
    const float w = t * t * t;
    acc += w * (sigma6 * w - 1.0f);
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  RAYCUT_HD static void mirror(Accumulator&) {}  // an energy: the same on both
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const {
    energy[i] = acc * four_epsilon_sigma6;
  }
};

// The per-target state of the kernels that write energy, force and virial: a pair's force factor
// g adds g r to the force and g r (x) r to the virial (xx yy zz xy xz yz); each kernel's finish()
// applies its constant factors.
struct EnergyForceVirial {
  float energy = 0, f[3] = {0, 0, 0}, v[6] = {0, 0, 0, 0, 0, 0};
  RAYCUT_HD void add_force(float g, Vec3 r) {
    const float gx = g * r.x, gy = g * r.y, gz = g * r.z;
    f[0] += gx;
    f[1] += gy;
    f[2] += gz;
    v[0] += gx * r.x;
    v[1] += gy * r.y;
    v[2] += gz * r.z;
    v[3] += gx * r.y;
    v[4] += gx * r.z;
    v[5] += gy * r.z;
  }
  RAYCUT_HD void add(const EnergyForceVirial& b) {
    energy += b.energy;
    for (int k = 0; k < 3; ++k) f[k] += b.f[k];
    for (int k = 0; k < 6; ++k) v[k] += b.v[k];
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
  using Accumulator = EnergyForceVirial;
  using options = functor_options<option::vanishes_at_infinity, option::combine, option::repeatable,
                                  option::mirror>;
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
    acc.add_force(g, r);
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a.add(b); }
  // j's term: the same energy and virial (r r is even in r), the opposite force.
  RAYCUT_HD static void mirror(Accumulator& a) {
    for (int k = 0; k < 3; ++k) a.f[k] = -a.f[k];
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
  using options = functor_options<option::combine, option::repeatable, option::mirror>;
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
  RAYCUT_HD static void mirror(Accumulator& a) {
    for (int k = 0; k < 3; ++k) a.f[k] = -a.f[k];
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const {
    energy[i] = acc.energy;
    for (int k = 0; k < 3; ++k) force[3 * std::size_t{i} + k] = acc.f[k];
  }
};

// rho_i contribution m W_poly6(r, h) = m 315 / (64 pi h^9) (h^2 - r^2)^3 (Mueller et al. 2003).
struct SphDensityKernel {
  using Accumulator = float;
  using options = functor_options<option::combine, option::repeatable, option::mirror>;
  float mass_poly6;  // m 315 / (64 pi h^9)
  float h_squared;
  float* density;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, Vec3, float r2) const {
    const float w = h_squared - r2;
    acc += w * w * w;
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  RAYCUT_HD static void mirror(Accumulator&) {}
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
  using options = functor_options<option::combine, option::repeatable>;
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

// Damped shifted-force (DSF) Coulomb, Fennell & Gezelter, J. Chem. Phys. 124, 234104 (2006) (the
// formula of LAMMPS's pair coul/dsf documentation; its per-atom self term too): with a = alpha and
//   phi(r)  = erfc(a r) / r - e_C + f_C (r - C),   e_C = erfc(a C) / C,
//   f_C     = erfc(a C) / C^2 + 2 a / sqrt(pi) exp(-a^2 C^2) / C,
//   phi'(r) = f_C - erfc(a r) / r^2 - 2 a / sqrt(pi) exp(-a^2 r^2) / r
// (phi and phi' are 0 at r = C: energy and force go to 0 at the cutoff),
//   energy_i = 1/2 k q_i sum_j q_j phi(r_ij) - (e_C / 2 + a / sqrt(pi)) k q_i^2   (self term)
//   force_i  = k q_i sum_j q_j phi'(r_ij) r_ij / r_ij           (r_ij = x_j - x_i)
//   virial_i = -1/2 sum_j r_ij (x) force_i(j)
// each pair's energy and virial half on each atom, as lj_forces: sum_i energy_i is the system's
// energy with its self energy. Per pair the terms without k q_i; finish() multiplies by them.
// Reads q_j (its pair call takes j). With query points q_i is the query's charge (CoulombInputs).
// Coincident pairs (r = 0) give non-finite terms (1 / r): the physics, as for lj.
struct CoulombDsfKernel {
  using Accumulator = EnergyForceVirial;
  using options = functor_options<option::combine, option::repeatable>;
  float alpha;                   // a
  float alpha_squared;           // a^2
  float two_alpha_over_sqrt_pi;  // 2 a / sqrt(pi)
  float cutoff;                  // C
  float energy_shift;            // e_C
  float force_shift;             // f_C
  float constant;                // k
  float self_factor;             // -(e_C / 2 + a / sqrt(pi)) k
  CoulombInputs in;
  float* energy;  // 1 per target
  float* force;   // 3 per target
  float* virial;  // 6 per target
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, std::uint32_t j, Vec3 r,
                            float r2) const {
    const float d = sqrtf(r2);
    const float inverse = 1.0f / d;
    const float q = in.charge[j];
    const float screened = erfcf(alpha * d) * inverse;  // erfc(a r) / r
    const float gaussian = two_alpha_over_sqrt_pi * expf(-alpha_squared * r2);
    acc.energy += q * (screened - energy_shift + force_shift * (d - cutoff));
    const float g = q * (force_shift - (screened + gaussian) * inverse) * inverse;  // q phi' / r
    acc.add_force(g, r);
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a.add(b); }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const {
    const float qi = in.query_charge ? in.query_charge[i] : in.charge[i];
    const float kq = constant * qi;
    energy[i] = 0.5f * kq * acc.energy + self_factor * qi * qi;
    for (int k = 0; k < 3; ++k) force[3 * std::size_t{i} + k] = kq * acc.f[k];
    for (int k = 0; k < 6; ++k) virial[6 * std::size_t{i} + k] = -0.5f * kq * acc.v[k];
  }
};

// ---- the catalogue of built-in kernels ---------------------------------------------------------
// One spec struct per kernel says everything about it: its name, the KernelOptions fields it reads
// (parameters, with their accepted ranges), its per-particle inputs, what it writes, how its
// functor is made and which of its float terms must stay in range. BuiltinKernels lists them in
// the order of enum Kernel. A type list (not an X-macro or an array of entries): each spec keeps
// its own functor type and code, the compiler generates every dispatch from the list (name
// lookup, produces, with_kernel, validate_kernel_range, validate_kernel_inputs, the OptiX launch
// parameters, Python's kernel_catalogue), and a kernel missing from a dispatch cannot happen.
// Adding a kernel: its functor, its spec, its enum value and its place in BuiltinKernels.

// A parameter: a float (accepted: finite values in [min, max]) or a flag of KernelOptions.
struct KernelParameter {
  std::string_view name;  // Python's keyword in Engine.compute (mostly the field's own name)
  float KernelOptions::*value = nullptr;
  bool KernelOptions::*flag = nullptr;
  double min = -std::numeric_limits<double>::infinity();
  double max = std::numeric_limits<double>::infinity();
};

// Where a per-particle input is indexed.
enum class InputEnd {
  both,     // at the target i and the source j, from one array: no query points
  sources,  // at the source j (and the target i without query points): one value per source
  queries,  // at the target i with query points only: one value per query
};

// A per-particle float input (a pointer field of KernelOptions).
struct KernelInput {
  std::string_view name;  // Python's keyword in Engine.compute
  std::uint32_t components;
  InputEnd end;
  bool positive;                                   // values must be > 0 (else: finite)
  const float*& (*field)(KernelOptions& options);  // the pointer it is passed in
};

// Reads an input's pointer from options (a copy of them: `field` hands out a mutable reference).
inline const float* input_pointer(const KernelInput& input, KernelOptions options) {
  return input.field(options);
}

// The outputs of KernelOutputs: name and floats (or counts) per target.
struct KernelOutputField {
  std::string_view name;
  std::uint32_t components;
  bool KernelProduces::*produced;
};
inline constexpr KernelOutputField kernel_output_fields[] = {
    {"count", 1, &KernelProduces::count},
    {"energy", 1, &KernelProduces::energy},
    {"force", 3, &KernelProduces::force},
    {"virial", 6, &KernelProduces::virial},
    {"density", 1, &KernelProduces::density}};

// The cutoff as the kernels see it (validate_kernel_range): C, the squared cutoff rounded to
// float, and h = its float square root.
struct KernelScale {
  double cutoff, c2, h;
};

// A range check: require(what, value, may_be_zero) throws when `value`, a float term of the kernel,
// overflows float or (unless exactly zero and may_be_zero) underflows it; a fourth and fifth
// argument give the cutoffs the kernel supports, for the message.
struct NoRangeCheck {
  template <class Require>
  static void check_range(const KernelOptions&, const KernelScale&, Require&&) {}
};

inline constexpr float kernel_pi = 3.14159265358979f;  // as every earlier result was computed
inline constexpr double range_pi = 3.14159265358979;   // the same, widened for range checks

struct CountSpec : NoRangeCheck {
  static constexpr Kernel id = Kernel::count;
  static constexpr std::string_view name = "count";
  static constexpr KernelProduces outputs{true, false, false, false, false};
  static constexpr std::array<KernelParameter, 0> parameters{};
  static constexpr std::array<KernelInput, 0> inputs{};
  static CountKernel make(const KernelOptions&, float, const KernelOutputs& out) {
    return {out.count};
  }
};

// The range check both Lennard-Jones kernels share.
struct LennardJonesRange {
  template <class Require>
  static void check_range(const KernelOptions& o, const KernelScale&, Require&& require) {
    const double sigma6 = std::pow(static_cast<double>(o.lj_sigma), 6);
    const bool zero = o.lj_sigma == 0.0f || o.lj_epsilon == 0.0f;
    require("sigma^6", sigma6, o.lj_sigma == 0.0f);
    require("factor 4 eps sigma^6", 4.0 * o.lj_epsilon * sigma6, zero);
  }
};
inline constexpr KernelParameter lj_epsilon_parameter{"lj_epsilon", &KernelOptions::lj_epsilon};
inline constexpr KernelParameter lj_sigma_parameter{"lj_sigma", &KernelOptions::lj_sigma};

struct LennardJonesSpec : LennardJonesRange {
  static constexpr Kernel id = Kernel::lj;
  static constexpr std::string_view name = "lj";
  static constexpr KernelProduces outputs{false, true, false, false, false};
  static constexpr std::array<KernelParameter, 2> parameters{lj_epsilon_parameter,
                                                             lj_sigma_parameter};
  static constexpr std::array<KernelInput, 0> inputs{};
  static LennardJonesKernel make(const KernelOptions& o, float, const KernelOutputs& out) {
    if (o.lj_shift)
      throw Error(ErrorCode::invalid_argument,
                  "kernel lj: lj_shift is not accepted (lj is the paper's per-target energy, "
                  "unshifted); use lj_forces for a shifted energy");
    const float sigma2 = o.lj_sigma * o.lj_sigma, sigma6 = sigma2 * sigma2 * sigma2;
    return {sigma6, 4.0f * o.lj_epsilon * sigma6, out.energy};
  }
};

struct LennardJonesForceSpec : LennardJonesRange {
  static constexpr Kernel id = Kernel::lj_forces;
  static constexpr std::string_view name = "lj_forces";
  static constexpr KernelProduces outputs{false, true, true, true, false};
  static constexpr std::array<KernelParameter, 3> parameters{
      lj_epsilon_parameter, lj_sigma_parameter, {"lj_shift", nullptr, &KernelOptions::lj_shift}};
  static constexpr std::array<KernelInput, 0> inputs{};
  static LennardJonesForceKernel make(const KernelOptions& o, float cutoff_squared,
                                      const KernelOutputs& out) {
    // u_C (u_C - 1) in double, u_C = (sigma^2 / C^2)^3.
    const float sigma2 = o.lj_sigma * o.lj_sigma;
    const double reduced = static_cast<double>(sigma2) / cutoff_squared;
    const double u_cut = reduced * reduced * reduced;
    const float shift = o.lj_shift ? static_cast<float>(u_cut * (u_cut - 1.0)) : 0.0f;
    return {sigma2, 4.0f * o.lj_epsilon, out.energy, out.force, out.virial, shift};
  }
};

struct SmoothSpec {
  static constexpr Kernel id = Kernel::smooth;
  static constexpr std::string_view name = "smooth";
  static constexpr KernelProduces outputs{false, true, true, false, false};
  static constexpr std::array<KernelParameter, 0> parameters{};
  static constexpr std::array<KernelInput, 0> inputs{};
  static SmoothKernel make(const KernelOptions&, float cutoff_squared, const KernelOutputs& out) {
    return {cutoff_squared, out.energy, out.force};
  }
  template <class Require>
  static void check_range(const KernelOptions&, const KernelScale& s, Require&& require) {
    const double lowest = std::pow(static_cast<double>(std::numeric_limits<float>::min()), 0.25);
    const double highest = std::pow(static_cast<double>(std::numeric_limits<float>::max()), 0.25);
    require("largest energy term (C^2)^2", s.c2 * s.c2, false, lowest, highest);
    require("largest force term C^2 * C", s.c2 * s.cutoff, false, lowest, highest);
  }
};

inline constexpr KernelParameter sph_mass_parameter{"sph_mass", &KernelOptions::sph_mass};

struct SphDensitySpec {
  static constexpr Kernel id = Kernel::sph_density;
  static constexpr std::string_view name = "sph_density";
  static constexpr KernelProduces outputs{false, false, false, false, true};
  static constexpr std::array<KernelParameter, 1> parameters{sph_mass_parameter};
  static constexpr std::array<KernelInput, 0> inputs{};
  static SphDensityKernel make(const KernelOptions& o, float cutoff_squared,
                               const KernelOutputs& out) {
    const float h = std::sqrt(cutoff_squared);
    const double h3 = static_cast<double>(h) * h * h;
    return {static_cast<float>(o.sph_mass * 315.0 / (64.0 * kernel_pi * h3 * h3 * h3)),
            cutoff_squared, out.density};
  }
  template <class Require>
  static void check_range(const KernelOptions& o, const KernelScale& s, Require&& require) {
    const double mass = o.sph_mass, c2 = s.c2;
    const double factor = mass * 315.0 / (64.0 * range_pi * std::pow(s.h, 9));
    require("factor m 315 / (64 pi h^9)", factor, mass == 0);
    require("largest raw term (h^2)^3", c2 * c2 * c2, false);
    require("largest pair term m 315 / (64 pi h^9) h^6", factor * c2 * c2 * c2, mass == 0);
  }
};

struct SphForceSpec {
  static constexpr Kernel id = Kernel::sph_force;
  static constexpr std::string_view name = "sph_force";
  static constexpr KernelProduces outputs{false, false, true, false, false};
  static constexpr std::array<KernelParameter, 2> parameters{
      sph_mass_parameter, {"sph_viscosity", &KernelOptions::sph_viscosity}};
  static constexpr std::array<KernelInput, 3> inputs{
      KernelInput{"velocity", 3, InputEnd::both, false,
                  [](KernelOptions& o) -> const float*& { return o.sph.velocity; }},
      KernelInput{"density", 1, InputEnd::both, true,
                  [](KernelOptions& o) -> const float*& { return o.sph.density; }},
      KernelInput{"pressure", 1, InputEnd::both, false,
                  [](KernelOptions& o) -> const float*& { return o.sph.pressure; }}};
  static SphForceKernel make(const KernelOptions& o, float cutoff_squared,
                             const KernelOutputs& out) {
    const float h = std::sqrt(cutoff_squared);
    const double h3 = static_cast<double>(h) * h * h;
    return {o.sph_mass,      h,     static_cast<float>(45.0 / (kernel_pi * h3 * h3)),
            o.sph_viscosity, o.sph, out.force};
  }
  template <class Require>
  static void check_range(const KernelOptions& o, const KernelScale& s, Require&& require) {
    const double mass = o.sph_mass, viscosity = o.sph_viscosity;
    const double spiky = 45.0 / (range_pi * std::pow(s.h, 6));
    require("factor 45 / (pi h^6)", spiky, false);
    require("pressure factor per unit p / rho, m 45 / (pi h^6)", mass * spiky, mass == 0);
    require("viscosity factor per unit v / rho, mu m 45 / (pi h^6)", viscosity * mass * spiky,
            viscosity * mass == 0);
    require("largest pressure term per unit p / rho, m 45 / (pi h^6) h^2", mass * spiky * s.c2,
            mass == 0);
    require("largest viscosity term per unit v / rho, mu m 45 / (pi h^6) h",
            viscosity * mass * spiky * s.h, viscosity * mass == 0);
  }
};

struct CoulombDsfSpec {
  static constexpr Kernel id = Kernel::coulomb_dsf;
  static constexpr std::string_view name = "coulomb_dsf";
  static constexpr KernelProduces outputs{false, true, true, true, false};
  static constexpr std::array<KernelParameter, 2> parameters{
      KernelParameter{"alpha", &KernelOptions::dsf_alpha, nullptr, 0.0},
      KernelParameter{"coulomb_constant", &KernelOptions::coulomb_constant}};
  static constexpr std::array<KernelInput, 2> inputs{
      KernelInput{"charge", 1, InputEnd::sources, false,
                  [](KernelOptions& o) -> const float*& { return o.coulomb.charge; }},
      KernelInput{"query_charge", 1, InputEnd::queries, false,
                  [](KernelOptions& o) -> const float*& { return o.coulomb.query_charge; }}};
  // The constants in double, rounded once.
  struct Constants {
    double energy_shift, force_shift, self_factor;
  };
  static Constants constants(double alpha, double cutoff, double k) {
    const double sqrt_pi = std::sqrt(3.14159265358979323846);
    const double erfc_c = std::erfc(alpha * cutoff);
    const double energy_shift = erfc_c / cutoff;
    const double force_shift =
        erfc_c / (cutoff * cutoff) +
        2.0 * alpha / sqrt_pi * std::exp(-alpha * alpha * cutoff * cutoff) / cutoff;
    return {energy_shift, force_shift, -(0.5 * energy_shift + alpha / sqrt_pi) * k};
  }
  static CoulombDsfKernel make(const KernelOptions& o, float cutoff_squared,
                               const KernelOutputs& out) {
    const double alpha = o.dsf_alpha, cutoff = std::sqrt(static_cast<double>(cutoff_squared));
    const Constants c = constants(alpha, cutoff, o.coulomb_constant);
    return {o.dsf_alpha,
            static_cast<float>(alpha * alpha),
            static_cast<float>(2.0 * alpha / std::sqrt(3.14159265358979323846)),
            static_cast<float>(cutoff),
            static_cast<float>(c.energy_shift),
            static_cast<float>(c.force_shift),
            o.coulomb_constant,
            static_cast<float>(c.self_factor),
            o.coulomb,
            out.energy,
            out.force,
            out.virial};
  }
  template <class Require>
  static void check_range(const KernelOptions& o, const KernelScale& s, Require&& require) {
    const double alpha = o.dsf_alpha, k = o.coulomb_constant;
    if (!(alpha >= 0.0) || !std::isfinite(alpha) || !std::isfinite(k))
      return;  // the parameter check names them
    constexpr double float_max = std::numeric_limits<float>::max();
    const double cutoff = std::sqrt(s.c2);
    require("Coulomb constant k", k, true);
    // Only overflow matters for these: a damping so strong that a term underflows to 0 is
    // the physics (erfc(a C) = 0), not a lost precision.
    auto no_overflow = [&](const char* what, double value) {
      if (!(std::fabs(value) <= float_max)) require(what, value, true);
    };
    const Constants c = constants(alpha, cutoff, k);
    no_overflow("alpha^2 C^2", alpha * alpha * s.c2);
    no_overflow("energy shift erfc(alpha C) / C", c.energy_shift);
    no_overflow("force shift erfc(alpha C) / C^2 + 2 alpha / sqrt(pi) exp(-alpha^2 C^2) / C",
                c.force_shift);
    no_overflow("self factor (erfc(alpha C) / (2 C) + alpha / sqrt(pi)) k", c.self_factor);
  }
};

template <class... Specs>
struct KernelList {};
using BuiltinKernels = KernelList<CountSpec, LennardJonesSpec, LennardJonesForceSpec, SmoothSpec,
                                  SphDensitySpec, SphForceSpec, CoulombDsfSpec>;

// Calls visit(Spec{}) for every built-in kernel, in the order of enum Kernel.
template <class Visit, class... Specs>
constexpr void for_each_kernel_in(KernelList<Specs...>, Visit&& visit) {
  (visit(Specs{}), ...);
}
template <class Visit>
constexpr void for_each_kernel(Visit&& visit) {
  for_each_kernel_in(BuiltinKernels{}, visit);
}

// Calls visit(Spec{}) with the spec of `kernel` (nothing for a value outside the enum).
template <class Visit>
constexpr void visit_kernel(Kernel kernel, Visit&& visit) {
  for_each_kernel([&](auto spec) {
    if (decltype(spec)::id == kernel) visit(spec);
  });
}

// The catalogue's order is the enum's: spec k has id k.
template <class... Specs>
constexpr bool ids_in_order(KernelList<Specs...>) {
  int k = 0;
  return ((static_cast<int>(Specs::id) == k++) && ...);
}
static_assert(ids_in_order(BuiltinKernels{}), "BuiltinKernels must list the kernels in enum order");

constexpr KernelProduces produces(Kernel kernel) {
  KernelProduces p{};
  visit_kernel(kernel, [&](auto spec) { p = decltype(spec)::outputs; });
  return p;
}

// Calls f(functor) with the built-in functor for `kernel`, writing to `out`: one dispatch, shared
// by every method. Throws Error(invalid_argument) when `out` lacks what the kernel writes or
// `options` an input it reads (the query-side ones are checked by validate_kernel_inputs).
template <class F>
void with_kernel(Kernel kernel, const KernelOptions& options, float cutoff_squared,
                 const KernelOutputs& out, F&& f) {
  visit_kernel(kernel, [&](auto spec) {
    using Spec = decltype(spec);
    constexpr KernelProduces p = Spec::outputs;
    if ((p.count && !out.count) || (p.energy && !out.energy) || (p.force && !out.force) ||
        (p.virial && !out.virial) || (p.density && !out.density))
      throw Error(ErrorCode::invalid_argument,
                  "kernel " + std::string(Spec::name) + ": an output it writes has a null pointer");
    for (const KernelInput& input : Spec::inputs)
      if (input.end != InputEnd::queries && !input_pointer(input, options)) {
        std::string needed;
        for (const KernelInput& other : Spec::inputs)
          if (other.end != InputEnd::queries)
            needed += (needed.empty() ? "" : ", ") + std::string(other.name);
        throw Error(ErrorCode::invalid_argument,
                    "kernel " + std::string(Spec::name) + " needs its per-particle inputs (" +
                        needed + "): " + std::string(input.name) + " is missing (null)");
      }
    f(Spec::make(options, cutoff_squared, out));
  });
}

}  // namespace raycut
