// Scenario construction follows the HIP RT sample (HIPRTSDK tutorials/16_fluid_simulation,
// main.cpp) arithmetic in float, so hiprt_drop's coordinates are the sample's bit for bit.
#include "sph/scenario.hpp"

#include <cmath>
#include <string>
#include <utility>

#include "raycut/error.hpp"

namespace raycut::sph {
namespace {

constexpr float pool_side = 1.0f;           // the pool is [-0.5, 0.5] x [0, 1] x [-0.5, 0.5]
constexpr float article_block_side = 0.6f;  // the article's water cube
constexpr int article_lattice_side = 51;    // ceil(cbrt(131072))
constexpr std::size_t article_particles = 131072;

// Smallest k with k^3 >= n; integer, so exact cubes do not depend on how std::cbrt rounds.
int lattice_side(std::size_t n) {
  std::size_t k = 1;
  while (k * k * k < n) ++k;
  return static_cast<int>(k);
}

SphParameters article_parameters(float particle_mass) {
  SphParameters p{};
  p.rest_density = 1000.0f;
  p.particle_mass = particle_mass;
  p.smoothing_length = pool_side / 50.0f;
  p.stiffness = 200.0f;
  p.viscosity = 0.4f;
  p.wall_stiffness = 3000.0f;
  p.gravity = {0.0f, -9.8f, 0.0f};
  p.dt = 1.0f / 320.0f;
  p.walls = {
      {{{0.0f, 1.0f, 0.0f}, 0.0f},                // floor y = 0
       {{0.0f, -1.0f, 0.0f}, pool_side},          // ceiling y = 1
       {{1.0f, 0.0f, 0.0f}, 0.5f * pool_side},    // x = -0.5
       {{-1.0f, 0.0f, 0.0f}, 0.5f * pool_side},   // x = +0.5
       {{0.0f, 0.0f, 1.0f}, 0.5f * pool_side},    // z = -0.5
       {{0.0f, 0.0f, -1.0f}, 0.5f * pool_side}},  // z = +0.5
  };
  return p;
}

// n particles of a lattice of `side` points per axis in a cube of edge block_side. As in the
// sample, point (ix, iy, iz) sits at corner + i * spacing (the first point is the cube's corner,
// the last is one spacing short of the opposite corner), x varies fastest, then y, then z, and the
// cube is centred at (-0.45 (L - a), L - a / 2, 0.45 (L - a)): it touches the ceiling and leans
// towards -x, +z, which for a = 0.6 is (-0.18, 0.70, 0.18).
SphScenario make_block(std::string name, std::size_t n, int side, float block_side) {
  const float rest_density = 1000.0f;
  const float volume = block_side * block_side * block_side;
  const float mass = rest_density * volume / static_cast<float>(n);
  const float centre[3] = {-0.45f * (pool_side - block_side), pool_side - block_side * 0.5f,
                           0.45f * (pool_side - block_side)};

  SphScenario s;
  s.name = std::move(name);
  s.params = article_parameters(mass);
  s.position.resize(3 * n);
  s.velocity.assign(3 * n, 0.0f);  // at rest
  const std::size_t row = static_cast<std::size_t>(side);
  const std::size_t slice = row * row;
  const float side_f = static_cast<float>(side);
  for (std::size_t i = 0; i < n; ++i) {
    const std::size_t in_slice = i % slice;
    const float unit[3] = {static_cast<float>(in_slice % row) / side_f,
                           static_cast<float>(in_slice / row) / side_f,
                           static_cast<float>(i / slice) / side_f};
    for (int a = 0; a < 3; ++a) s.position[3 * i + a] = block_side * (unit[a] - 0.5f) + centre[a];
  }
  s.frames = 200;
  s.image_frame = 165;
  return s;
}

bool positive_finite(float x) {
  return std::isfinite(x) && x > 0.0f;
}

void require(bool ok, ErrorCode code, const std::string& what) {
  if (!ok) throw Error(code, what);
}

}  // namespace

SphScenario hiprt_drop() {
  return make_block("hiprt-drop", article_particles, article_lattice_side, article_block_side);
}

SphScenario small_drop(std::size_t n) {
  require(n > 0, ErrorCode::invalid_argument, "small_drop: n must be > 0");
  // Past 85^3 particles the block at the article's spacing no longer fits in the pool.
  constexpr std::size_t max_particles = 85 * 85 * 85;
  require(n <= max_particles, ErrorCode::invalid_argument,
          "small_drop: n = " + std::to_string(n) + " gives a block larger than the pool (at most " +
              std::to_string(max_particles) + " particles)");
  const int side = lattice_side(n);
  // Rounded from double so that side = 51 gives exactly the article's 0.6f.
  const float block_side =
      static_cast<float>(double{article_block_side} * side / article_lattice_side);
  return make_block("small-drop", n, side, block_side);
}

void validate(const SphScenario& s) {
  const SphParameters& p = s.params;
  const auto bad = [&](const char* field) {
    return "scenario '" + s.name + "': " + field + " must be finite and > 0";
  };
  require(positive_finite(p.rest_density), ErrorCode::invalid_argument, bad("rest_density"));
  require(positive_finite(p.particle_mass), ErrorCode::invalid_argument, bad("particle_mass"));
  require(positive_finite(p.smoothing_length), ErrorCode::invalid_argument,
          bad("smoothing_length"));
  require(positive_finite(p.stiffness), ErrorCode::invalid_argument, bad("stiffness"));
  require(positive_finite(p.dt), ErrorCode::invalid_argument, bad("dt"));
  // Zero viscosity, wall stiffness or gravity are legitimate (the momentum-conservation test).
  require(std::isfinite(p.viscosity) && p.viscosity >= 0.0f, ErrorCode::invalid_argument,
          "scenario '" + s.name + "': viscosity must be finite and >= 0");
  require(std::isfinite(p.wall_stiffness) && p.wall_stiffness >= 0.0f, ErrorCode::invalid_argument,
          "scenario '" + s.name + "': wall_stiffness must be finite and >= 0");
  for (float g : p.gravity) {
    require(std::isfinite(g), ErrorCode::invalid_argument,
            "scenario '" + s.name + "': gravity must be finite");
  }
  for (std::size_t w = 0; w < p.walls.size(); ++w) {
    const WallPlane& wall = p.walls[w];
    const float norm2 = wall.normal[0] * wall.normal[0] + wall.normal[1] * wall.normal[1] +
                        wall.normal[2] * wall.normal[2];
    require(std::isfinite(wall.d) && std::abs(norm2 - 1.0f) < 1e-5f, ErrorCode::invalid_argument,
            "scenario '" + s.name + "': wall " + std::to_string(w) +
                " needs a unit normal and a finite d");
  }
  require(s.frames >= 0 && (s.frames == 0 || (s.image_frame >= 0 && s.image_frame < s.frames)),
          ErrorCode::invalid_argument,
          "scenario '" + s.name + "': frames must be >= 0 and image_frame in [0, frames)");
  require(s.position.size() % 3 == 0 && s.velocity.size() == s.position.size(),
          ErrorCode::invalid_input,
          "scenario '" + s.name + "': position and velocity must both hold N * 3 floats (" +
              std::to_string(s.position.size()) + " and " + std::to_string(s.velocity.size()) +
              ")");
  const std::size_t n = s.position.size() / 3;
  for (std::size_t i = 0; i < n; ++i) {
    const float* x = &s.position[3 * i];
    const float* v = &s.velocity[3 * i];
    const bool finite = std::isfinite(x[0]) && std::isfinite(x[1]) && std::isfinite(x[2]) &&
                        std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
    require(finite, ErrorCode::invalid_input,
            "scenario '" + s.name + "': non-finite position or velocity at particle index " +
                std::to_string(i));
    for (std::size_t w = 0; w < p.walls.size(); ++w) {
      const WallPlane& wall = p.walls[w];
      const float inside =
          wall.normal[0] * x[0] + wall.normal[1] * x[1] + wall.normal[2] * x[2] + wall.d;
      require(inside >= 0.0f, ErrorCode::invalid_input,
              "scenario '" + s.name + "': particle index " + std::to_string(i) +
                  " is outside the pool (wall " + std::to_string(w) + ")");
    }
  }
}

}  // namespace raycut::sph
