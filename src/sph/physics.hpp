// The per-particle arithmetic of the SPH step (docs/sph.md, Mueller et al. 2003): density with
// the self contribution, the equation of state (the article's clamped cubic one, or Tait's of the
// weakly compressible mode, docs/sph-validation.md), and the wall + gravity acceleration with
// the semi-implicit Euler update (fixed boundary particles of the weakly compressible mode never
// move). ONE implementation: the host loop of the CPU methods and the
// CUDA kernels of src/sph/device_steps.cu both call these functions. No CUDA types; RAYCUT_HD makes
// them __host__ __device__ under nvcc and plain inline elsewhere.
#pragma once

#include "raycut/predicate.hpp"  // RAYCUT_HD

namespace raycut::sph {

// Equation of state (StepConstants::equation_of_state).
enum : int {
  eos_article = 0,  // p = k ((rho / rho0)^3 - 1), clamped at >= 0 (the article's sample)
  eos_tait = 1,     // p = B ((rho / rho0)^7 - 1), B = c0^2 rho0 / 7; clamped at >= 0 if asked
};

// Everything a per-particle step needs, by value (a kernel argument): plain floats and ints only.
struct StepConstants {
  float self_density;    // m W_poly6(0, h) = m 315 / (64 pi h^3): the j = i term of rho_i
  float rest_density;    // rho0
  float stiffness;       // k in p = k ((rho / rho0)^3 - 1), clamped at >= 0
  float wall_stiffness;  // k_wall
  float gravity[3];
  float dt;
  float wall_normal[6][3];  // s = dot(n, x) + d >= 0 inside the pool
  float wall_d[6];
  int equation_of_state;  // eos_article or eos_tait
  float tait_b;           // B = c0^2 rho0 / gamma (eos_tait)
  int clamp_negative;     // eos_tait: 1 clamps p at >= 0, 0 keeps negative pressure
  float velocity_keep;    // integrate_or_hold: v = (v + dt a) * velocity_keep; 1 / (1 + dt k)
                          // for a settling damping of rate k [1/s], 1 without
};

// rho_i from the engine's sum over neighbours j != i (Kernel::sph_density).
RAYCUT_HD float density_with_self(float neighbour_sum, const StepConstants& c) {
  return neighbour_sum + c.self_density;
}

// Tait: p = B ((rho / rho0)^7 - 1), optionally clamped at >= 0.
RAYCUT_HD float tait_pressure(float rho, const StepConstants& c) {
  const float ratio = rho / c.rest_density;
  const float r2 = ratio * ratio;
  const float r7 = r2 * r2 * r2 * ratio;
  const float p = c.tait_b * (r7 - 1.0f);
  return (c.clamp_negative && p < 0.0f) ? 0.0f : p;
}

// The article's p = k ((rho / rho0)^3 - 1), negative pressure clamped to zero as the HIP RT
// sample does; or Tait's (eos_tait).
RAYCUT_HD float pressure_of(float rho, const StepConstants& c) {
  if (c.equation_of_state == eos_tait) return tait_pressure(rho, c);
  const float ratio = rho / c.rest_density;
  const float p = c.stiffness * (ratio * ratio * ratio - 1.0f);
  return p > 0.0f ? p : 0.0f;
}

// One particle's acceleration: a = f / rho (0 when rho = 0), the six wall penalties
// a += min(s, 0) (-k_wall) n, and gravity. x and force point at the particle's three components.
RAYCUT_HD void acceleration(const float* x, const float* force, float rho, const StepConstants& c,
                            float a[3]) {
  const float inv_rho = rho > 0.0f ? 1.0f / rho : 0.0f;
  for (int k = 0; k < 3; ++k) a[k] = force[k] * inv_rho;
  for (int w = 0; w < 6; ++w) {
    const float* n = c.wall_normal[w];
    const float s = n[0] * x[0] + n[1] * x[1] + n[2] * x[2] + c.wall_d[w];
    if (s < 0.0f) {
      const float push = -s * c.wall_stiffness;  // min(s, 0) * (-k_wall) >= 0
      a[0] += push * n[0];
      a[1] += push * n[1];
      a[2] += push * n[2];
    }
  }
  for (int k = 0; k < 3; ++k) a[k] += c.gravity[k];
}

// The article's integration: semi-implicit Euler, v += dt a, then x += dt v.
RAYCUT_HD void integrate_particle(float* x, float* v, const float* force, float rho,
                                  const StepConstants& c) {
  float a[3];
  acceleration(x, force, rho, c, a);
  for (int k = 0; k < 3; ++k) {
    v[k] += c.dt * a[k];
    x[k] += c.dt * v[k];
  }
}

// The weakly compressible mode's integration: as integrate_particle, with the settling damping
// v = (v + dt a) / (1 + dt k), unless the particle is a fixed boundary particle (fixed != 0):
// those keep their position and zero velocity (dynamic boundary conditions: they only lend
// density and pressure to the fluid).
RAYCUT_HD void integrate_or_hold(float* x, float* v, const float* force, float rho, float fixed,
                                 const StepConstants& c) {
  if (fixed != 0.0f) return;
  float a[3];
  acceleration(x, force, rho, c, a);
  for (int k = 0; k < 3; ++k) {
    v[k] = (v[k] + c.dt * a[k]) * c.velocity_keep;
    x[k] += c.dt * v[k];
  }
}

}  // namespace raycut::sph
