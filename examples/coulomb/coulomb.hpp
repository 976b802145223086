// Shifted-force Coulomb with a cutoff, as a raycut pair functor (include/raycut/kernels.hpp says
// the shape). For a pair at distance r < rc, with k = 1 (units where 1 / (4 pi eps0) = 1):
//   U(r) = q_i q_j (1/r - 1/rc + (r - rc) / rc^2)          energy and force are 0 at rc
//   F_i  = -dU/dx_i = -q_i q_j (1/r^2 - 1/rc^2) r_ij / r    r_ij = x_j - x_i
// Per target: energy_i = 1/2 sum_j U(r_ij) (so the total energy is sum_i energy_i) and force_i.
// Coincident pairs (r = 0) have no direction and are skipped. The same header serves the CPU
// program (raycut::for_each_pair) and the CUDA one (raycut::cuda::for_each_pair): RAYCUT_HD is
// __host__ __device__ under nvcc and inline otherwise.
#pragma once

#include <raycut/kernels.hpp>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <vector>

namespace coulomb {

struct ShiftedForce {
  struct Accumulator {
    float energy = 0, f[3] = {0, 0, 0};
  };
  // No option::vanishes_at_infinity: at r2 = +inf the terms are NaN (r * (1/r)), so out-of-range
  // pairs must never reach operator(). combine() lets GPU lanes share a target.
  using options = raycut::functor_options<raycut::option::combine>;

  const float* charge;  // 1 per particle, in the engine's memory space
  float rc, inv_rc, inv_rc2;
  float* energy;  // 1 per target
  float* force;   // 3 per target

  static ShiftedForce make(const float* charge, float cutoff, float* energy, float* force) {
    return {charge, cutoff, 1.0f / cutoff, 1.0f / (cutoff * cutoff), energy, force};
  }

  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t i, std::uint32_t j, raycut::Vec3 r,
                            float r2) const {
    if (r2 == 0.0f) return;
    const float inv_r = 1.0f / std::sqrt(r2);
    const float d = r2 * inv_r;
    const float qq = charge[i] * charge[j];
    acc.energy += qq * (inv_r - inv_rc + (d - rc) * inv_rc2);
    const float g = qq * (inv_r * inv_r - inv_rc2) * inv_r;
    acc.f[0] -= g * r.x;
    acc.f[1] -= g * r.y;
    acc.f[2] -= g * r.z;
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) {
    a.energy += b.energy;
    for (int k = 0; k < 3; ++k) a.f[k] += b.f[k];
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const {
    energy[i] = 0.5f * acc.energy;
    for (int k = 0; k < 3; ++k) force[3 * std::size_t{i} + k] = acc.f[k];
  }
};

// A small test system: n particles uniform in a cube (about 30 neighbours each within `cutoff`),
// charges +1 and -1 alternating. Own generator: the same numbers everywhere.
struct System {
  std::vector<float> xyz, charge;
  float cutoff = 0;
};

inline System make_system(std::size_t n, float cutoff) {
  System s;
  s.cutoff = cutoff;
  const double side = cutoff * std::cbrt(n * 4.18879 / 30.0);  // (4/3) pi rc^3 n / side^3 = 30
  std::uint64_t state = 0x9E3779B97F4A7C15ull;
  const auto next = [&] {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) * 0x1.0p-53;
  };
  for (std::size_t i = 0; i < n; ++i) {
    for (int k = 0; k < 3; ++k) s.xyz.push_back(static_cast<float>(side * next()));
    s.charge.push_back(i % 2 ? -1.0f : 1.0f);
  }
  return s;
}

// The check: every pair in double precision, O(N^2), against the functor's float results, per
// target, relative to the sum of the magnitudes of the target's terms (float round-off is ~1e-7
// of that; shifted force is continuous at rc, so pairs within round-off of the cutoff, which
// float and double may decide differently, change nothing measurable). Returns the worst ratio.
inline double worst_error(const System& s, const std::vector<float>& energy,
                          const std::vector<float>& force) {
  const std::size_t n = s.charge.size();
  const double rc = s.cutoff;
  double worst = 0;
  for (std::size_t i = 0; i < n; ++i) {
    double e = 0, f[3] = {0, 0, 0}, e_scale = 1e-30, f_scale = 1e-30;
    for (std::size_t j = 0; j < n; ++j) {
      if (j == i) continue;
      double r[3], r2 = 0;
      for (int k = 0; k < 3; ++k) {
        r[k] = static_cast<double>(s.xyz[3 * j + k]) - s.xyz[3 * i + k];
        r2 += r[k] * r[k];
      }
      if (r2 >= rc * rc || r2 == 0) continue;
      const double d = std::sqrt(r2), qq = static_cast<double>(s.charge[i]) * s.charge[j];
      e += 0.5 * qq * (1 / d - 1 / rc + (d - rc) / (rc * rc));
      e_scale += 0.5 * std::abs(qq) / d;
      const double g = qq * (1 / r2 - 1 / (rc * rc)) / d;
      for (int k = 0; k < 3; ++k) f[k] -= g * r[k];
      f_scale += std::abs(qq) / r2;
    }
    worst = std::max(worst, std::abs(energy[i] - e) / e_scale);
    for (int k = 0; k < 3; ++k)
      worst = std::max(worst, std::abs(force[3 * i + k] - f[k]) / f_scale);
  }
  return worst;
}

}  // namespace coulomb
