// The SPH solver's per-particle passes on the CUDA device, behind plain functions over raw device
// pointers (no CUDA types here): defined in device_steps.cu, compiled only when RAYCUT_HAVE_CUDA.
// Each launches one kernel on the default stream (the stream the engine's methods use, so the
// order with Engine::run is kept) over the arithmetic of sph/physics.hpp.
#pragma once

#include <cstddef>

#include "sph/physics.hpp"

namespace raycut::sph::device {

// rho[i] = density_with_self(neighbour_density[i]); p[i] = pressure_of(rho[i]).
// neighbour_density may be null (no neighbours at all: N = 0 or the results are empty).
void density_and_pressure(const float* neighbour_density, float* rho, float* p, std::size_t n,
                          const StepConstants& c);

// integrate_particle for every particle: x, v and force are (n, 3), rho has n values. fixed
// (n values, or null for none: integrate_particle, the article's model) marks the boundary
// particles of the weakly compressible mode (integrate_or_hold).
void integrate(float* x, float* v, const float* force, const float* rho, const float* fixed,
               std::size_t n, const StepConstants& c);

// Copies n floats device -> host (synchronous).
void copy_to_host(float* host, const float* device_values, std::size_t n);

// Waits for the device (for the synchronised per-pass timings); throws Error(backend) on a
// failed kernel.
void synchronize();

}  // namespace raycut::sph::device
