// The host side of the SPH step, shared by the single-process solver (src/sph/solver.cpp) and the
// distributed one (src/mpi/sph.cpp): the StepConstants of a scenario's parameters (both memory
// spaces take them) and the OpenMP loops of the CPU methods over the per-particle arithmetic of
// sph/physics.hpp, the host counterpart of sph/device_steps.hpp (the same signatures).
#pragma once

#include <cstddef>

#include "raycut/detail/host_threads.hpp"
#include "raycut/sph/scenario.hpp"
#include "sph/physics.hpp"

namespace raycut::sph {

inline StepConstants constants_of(const SphParameters& p) {
  StepConstants c{};
  const double pi = 3.14159265358979323846;
  const double h = p.smoothing_length;
  // m W_poly6(0, h) = m 315 / (64 pi h^9) h^6, in double then rounded once.
  c.self_density = static_cast<float>(p.particle_mass * 315.0 / (64.0 * pi * h * h * h));
  c.rest_density = p.rest_density;
  c.stiffness = p.stiffness;
  c.wall_stiffness = p.wall_stiffness;
  for (int k = 0; k < 3; ++k) c.gravity[k] = p.gravity[k];
  c.dt = p.dt;
  for (int w = 0; w < 6; ++w) {
    for (int k = 0; k < 3; ++k) c.wall_normal[w][k] = p.walls[w].normal[k];
    c.wall_d[w] = p.walls[w].d;
  }
  c.equation_of_state = p.weakly_compressible ? eos_tait : eos_article;
  // B = c0^2 rho0 / gamma, gamma = 7 (in double, rounded once).
  c.tait_b = static_cast<float>(double{p.sound_speed} * p.sound_speed * p.rest_density / 7.0);
  c.clamp_negative = p.clamp_negative_pressure ? 1 : 0;
  c.velocity_keep = 1.0f;  // per step: velocity_keep_at
  return c;
}

// StepConstants::velocity_keep of a step that starts at `time`: the settling damping's
// 1 / (1 + dt k) while time < damping_time, else 1.
inline float velocity_keep_at(const SphParameters& p, double time) {
  const bool damped = p.damping > 0.0f && time < p.damping_time;
  return damped ? 1.0f / (1.0f + p.dt * p.damping) : 1.0f;
}

namespace host {

// rho[i] = density_with_self(neighbour_density[i]); p[i] = pressure_of(rho[i]).
// neighbour_density may be null (no neighbours: N = 0).
inline void density_and_pressure(const float* neighbour_density, float* rho, float* p,
                                 std::size_t n, const StepConstants& c) {
  raycut::detail::for_each_index(n, raycut::detail::parallel_items, 0, [&](std::size_t i) {
    rho[i] = density_with_self(neighbour_density ? neighbour_density[i] : 0.0f, c);
    p[i] = pressure_of(rho[i], c);
  });
}

// integrate_particle for every particle (integrate_or_hold where `fixed`, n values, marks the
// weakly compressible mode's boundary particles; null: none). force may be null (no force).
inline void integrate(float* x, float* v, const float* force, const float* rho, const float* fixed,
                      std::size_t n, const StepConstants& c) {
  const float zero[3] = {0.0f, 0.0f, 0.0f};
  raycut::detail::for_each_index(n, raycut::detail::parallel_items, 0, [&](std::size_t i) {
    const float* f = force ? &force[3 * i] : zero;
    if (fixed)
      integrate_or_hold(&x[3 * i], &v[3 * i], f, rho[i], fixed[i], c);
    else
      integrate_particle(&x[3 * i], &v[3 * i], f, rho[i], c);
  });
}

}  // namespace host
}  // namespace raycut::sph
