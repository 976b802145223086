// The SPH scenarios of spec/SPH.md: the HIP RT article's falling block of water in a 1 m^3 pool,
// and a small version of it for CI on the CPU methods. Solver-independent: plain data in, no
// engine.
#pragma once

#include <array>
#include <cstddef>
#include <string>
#include <vector>

namespace raycut::sph {

// A wall half-space: s = dot(normal, x) + d, with s >= 0 inside the pool (normal points inside).
struct WallPlane {
  std::array<float, 3> normal;
  float d;
};

// The model constants of spec/SPH.md, in SI units. Floats, as the sample and the GPU solver use.
struct SphParameters {
  float rest_density;      // rho0 [kg/m^3]
  float particle_mass;     // m [kg], the same for every particle
  float smoothing_length;  // h [m], also the interaction cutoff
  float stiffness;         // k [Pa] in p = k ((rho / rho0)^3 - 1), clamped at >= 0
  float viscosity;         // mu
  float wall_stiffness;    // k_wall [1/s^2]: a += min(s, 0) * (-k_wall) * normal
  std::array<float, 3> gravity;
  float dt;  // [s], one step per frame
  std::array<WallPlane, 6> walls;
};

struct SphScenario {
  std::string name;
  SphParameters params;
  std::vector<float> position;  // (N, 3) row-major
  std::vector<float> velocity;  // (N, 3) row-major
  int frames;                   // steps to run (one step per frame)
  int image_frame;              // the frame the article renders, in [0, frames)
};

// The article's run, exactly (spec/SPH.md): 131,072 particles, the first 131,072 points of a
// 51^3 lattice with spacing 0.6/51 m whose corner point is the corner of the 0.6 m cube centred at
// (-0.18, 0.70, 0.18); x varies fastest, then y, then z (the last z slice is partial). 200 frames,
// dt = 1/320 s, image of frame 165.
SphScenario hiprt_drop();

// The same pool and physics with a block of exactly n particles on the same lattice spacing
// (0.6/51 m), so the particles sit as close as in hiprt_drop and the block has density rho0:
// side = ceil(cbrt(n)) * spacing, m = rho0 * side^3 / n, and the block is placed by the article's
// rule (touching the ceiling, offset towards -x, +z). n = 131072 gives hiprt_drop's particles.
// Throws raycut::Error (invalid_argument) for n = 0 or a block larger than the pool.
SphScenario small_drop(std::size_t n = 4000);

// Checks what a solver relies on: positive finite constants, unit wall normals, N * 3 finite
// coordinates and velocities, every particle inside the pool, 0 <= image_frame < frames.
// Throws raycut::Error (invalid_argument or invalid_input) naming the field or particle index.
void validate(const SphScenario& scenario);

}  // namespace raycut::sph
