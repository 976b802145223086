// The SPH scenarios of docs/sph.md: the HIP RT article's falling block of water in a 1 m^3 pool,
// a small version of it for CI on the CPU methods, and the weakly compressible validation
// scenarios (hydrostatic column, Martin & Moyce dam break; docs/sph-validation.md).
// Solver-independent: plain data in, no engine.
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

// The model constants of the article's sample (docs/sph.md), in SI units. Floats, as the sample and
// the GPU solver use.
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
  // The weakly compressible mode (docs/sph-validation.md). Off (the article's model) by default.
  // With it, Tait's p = B ((rho / rho0)^7 - 1), B = c0^2 rho0 / 7, replaces the cubic law
  // (stiffness is then unused), and the force pass runs Kernel::sph_force with 2 m and mu / 2
  // (so its pressure term is the consistent -sum m (p_i + p_j) / (rho_i rho_j) grad W once divided
  // by rho_i, and the viscosity term is unchanged: mu sum m (v_j - v_i) / rho_j lap W).
  bool weakly_compressible = false;
  float sound_speed = 0.0f;             // c0 [m/s]
  bool clamp_negative_pressure = true;  // p = max(p, 0) (Tait)
  // 1 / C, C = sum_j (m / rho0) (x_ij . e)^2 |grad W_spiky| / r over the initial lattice (1 in the
  // continuum; 0.947 for h = 2 dx): the force pass's pressure term is multiplied by it, so that
  // a linear pressure field's gradient comes out exact on the lattice (a scalar, and so still
  // momentum-conserving, form of the kernel-gradient renormalisation). 1: none.
  float gradient_correction = 1.0f;
  // Settling: velocities damped at rate `damping` [1/s] while t < damping_time (a relaxation to
  // the static equilibrium, which it does not change). 0: none.
  float damping = 0.0f;
  float damping_time = 0.0f;
};

struct SphScenario {
  std::string name;
  SphParameters params;
  std::vector<float> position;  // (N, 3) row-major
  std::vector<float> velocity;  // (N, 3) row-major
  int frames;                   // steps to run (one step per frame)
  int image_frame;              // the frame the article renders, in [0, frames)
  // Per particle (N values) 1 for a fixed boundary particle (gets density and pressure, never
  // moves; it may sit outside the wall planes), 0 for fluid; empty: all fluid.
  std::vector<float> fixed;
};

// The weakly compressible validation scenarios; every field is a key of the scenario file
// (read_wcsph_config). Lengths in m, SI units. The fluid and the tank's inside start at the
// origin: x in [0, tank_length], y >= 0, z in [0, column_width]; particles sit at the centres of
// a cubic lattice of spacing dx = column_width / resolution.
struct WcsphConfig {
  std::string scenario = "dam-break";  // "dam-break" or "hydrostatic"
  float column_width = 0.1f;           // a: the column's width in x and z (the tank's width in z)
  float column_height = 0.0f;  // H; 0: 2 a (Martin & Moyce's n^2 = 2; the hydrostatic column too)
  float tank_length = 0.0f;    // tank's inside length in x; 0: 5 a (dam break), a (hydrostatic)
  int resolution = 10;         // particles across a
  float h_over_dx = 2.0f;      // h (the kernels' support radius) / dx
  float sound_speed = 0.0f;    // c0; 0: 10 x the largest expected speed (c0())
  float cfl = 0.25f;           // the CFL, force and viscous conditions' coefficient (0.25)
  float viscosity_alpha = 0.04f;  // Monaghan's alpha: mu = rho0 alpha h c0 / 20
  float rest_density = 1000.0f;
  float gravity = 9.81f;
  int boundary_layers = 3;
  bool clamp_negative_pressure = true;
  float end_time = 0.0f;  // s; 0: T = t sqrt(2 g / a) = 3.3 (dam break), 0.5 s (hydrostatic)
  // Settling damping rate [1/s] while t < damping_time; < 0: the scenario's default (hydrostatic:
  // c0 / H for 0.3 s, then undamped; dam-break: none).
  float damping = -1.0f;
  float damping_time = -1.0f;

  float dx() const { return column_width / static_cast<float>(resolution); }
  float height() const { return column_height > 0.0f ? column_height : 2.0f * column_width; }
  float length() const {
    return tank_length > 0.0f ? tank_length
                              : (scenario == "dam-break" ? 5.0f : 1.0f) * column_width;
  }
  // sound_speed, or 10 x the largest expected flow speed: 10 sqrt(2 g H) for the hydrostatic
  // column (a free fall from the top), 20 sqrt(g H) for the dam break (Ritter's front speed
  // 2 sqrt(g H), which the surge tip reaches and sqrt(2 g H) underestimates).
  float c0() const;
  float viscosity() const;  // mu = rho0 alpha h c0 / 20
  float run_time() const;   // end_time or its default
};

// The time-step conditions of the weakly compressible mode, each in s, with Monaghan's
// smoothing length h_M = h / 2 (our h is the kernels' support radius, 2 h_M):
//   CFL      coefficient * h_M / (c0 + |v|max)
//   force    coefficient * sqrt(h_M / |a|max)       (infinite for |a|max = 0)
//   viscous  coefficient / 2 * h_M^2 rho0 / mu      (0.125 for coefficient 0.25; infinite for mu =
//   0)
struct TimeStepLimits {
  double cfl, force, viscous;
  double dt() const;  // the smallest
};
TimeStepLimits wcsph_time_step(float h, float c0, float max_speed, float max_acceleration,
                               float rest_density, float viscosity, float coefficient = 0.25f);

// The scenario of `config`: fluid particles, then boundary_layers layers of fixed particles on
// the floor and the four side walls (up to the tank's height, H + 2 dx, open top), the safety
// wall planes at the innermost boundary layer's centres (a stiff penalty only a particle that got
// through the boundary particles feels), m = rho0 / sum_lattice W_poly6 (an inner particle of the
// initial lattice has density rho0 exactly), and the fixed dt of wcsph_time_step with
// |v|max = c0 / 10 and |a|max = 100 g. Throws Error(invalid_argument) for bad values.
SphScenario wcsph_scenario(const WcsphConfig& config);

// Reads `key = value` lines (# comments, blank lines) over `base`; keys are WcsphConfig's fields,
// plus dx (sets resolution = round(column_width / dx)), c0 (= sound_speed) and
// negative_pressure = clamp | keep. Throws Error(io) or Error(invalid_argument) naming the line.
WcsphConfig read_wcsph_config(const std::string& path, WcsphConfig base = {});
// One `key = value` assignment (the file's and the CLI's shared parser).
void set_wcsph_key(WcsphConfig& config, const std::string& key, const std::string& value);

// The article's run, exactly: 131,072 particles, the first 131,072 points of a
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
