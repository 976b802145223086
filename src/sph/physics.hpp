// The per-particle arithmetic of the SPH step (spec/SPH.md, Mueller et al. 2003): density with
// the self contribution, the clamped equation of state, and the wall + gravity acceleration with
// the semi-implicit Euler update. ONE implementation: the host loop of the CPU methods and the
// CUDA kernels of src/sph/device_steps.cu both call these functions. No CUDA types; RAYCUT_HD makes
// them __host__ __device__ under nvcc and plain inline elsewhere.
#pragma once

#include "raycut/predicate.hpp"  // RAYCUT_HD

namespace raycut::sph {

// Everything a per-particle step needs, by value (a kernel argument): plain floats only.
struct StepConstants {
  float self_density;    // m W_poly6(0, h) = m 315 / (64 pi h^3): the j = i term of rho_i
  float rest_density;    // rho0
  float stiffness;       // k in p = k ((rho / rho0)^3 - 1), clamped at >= 0
  float wall_stiffness;  // k_wall
  float gravity[3];
  float dt;
  float wall_normal[6][3];  // s = dot(n, x) + d >= 0 inside the pool
  float wall_d[6];
};

// rho_i from the engine's sum over neighbours j != i (Kernel::sph_density).
RAYCUT_HD float density_with_self(float neighbour_sum, const StepConstants& c) {
  return neighbour_sum + c.self_density;
}

// p = k ((rho / rho0)^3 - 1), negative pressure clamped to zero as the HIP RT sample does.
RAYCUT_HD float pressure_of(float rho, const StepConstants& c) {
  const float ratio = rho / c.rest_density;
  const float p = c.stiffness * (ratio * ratio * ratio - 1.0f);
  return p > 0.0f ? p : 0.0f;
}

// One particle's integration: a = f / rho (0 when rho = 0), the six wall penalties
// a += min(s, 0) (-k_wall) n, gravity, then v += dt a and x += dt v. x and v point at the
// particle's three components.
RAYCUT_HD void integrate_particle(float* x, float* v, const float* force, float rho,
                                  const StepConstants& c) {
  const float inv_rho = rho > 0.0f ? 1.0f / rho : 0.0f;
  float a[3] = {force[0] * inv_rho, force[1] * inv_rho, force[2] * inv_rho};
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
  for (int k = 0; k < 3; ++k) {
    a[k] += c.gravity[k];
    v[k] += c.dt * a[k];
    x[k] += c.dt * v[k];
  }
}

}  // namespace raycut::sph
