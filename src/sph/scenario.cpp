// Scenario construction follows the HIP RT sample (HIPRTSDK tutorials/16_fluid_simulation,
// main.cpp) arithmetic in float, so hiprt_drop's coordinates are the sample's bit for bit.
#include "raycut/sph/scenario.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>
#include <utility>

#include "raycut/error.hpp"
#include "raycut/host_memory.hpp"
#include "raycut/sph/solver.hpp"
#include "raycut/tools/files.hpp"

namespace raycut::sph {
namespace {

// Host bytes a weakly compressible run holds per particle, an estimate from below: the scenario
// (position, velocity, fixed: 28), the solver's state (x, v, rho, p, fixed: 36), the kernels'
// results and the neighbour search's sorted copy (about 64), the CLI's copies of the state (64).
constexpr double run_bytes_per_particle = 192;

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
  require(s.fixed.empty() || s.fixed.size() == n, ErrorCode::invalid_input,
          "scenario '" + s.name + "': fixed must be empty or hold N values");
  require(!p.weakly_compressible || positive_finite(p.sound_speed), ErrorCode::invalid_argument,
          bad("sound_speed"));
  for (std::size_t i = 0; i < n; ++i) {
    const float* x = &s.position[3 * i];
    const float* v = &s.velocity[3 * i];
    const bool finite = std::isfinite(x[0]) && std::isfinite(x[1]) && std::isfinite(x[2]) &&
                        std::isfinite(v[0]) && std::isfinite(v[1]) && std::isfinite(v[2]);
    require(finite, ErrorCode::invalid_input,
            "scenario '" + s.name + "': non-finite position or velocity at particle index " +
                std::to_string(i));
    if (!s.fixed.empty() && s.fixed[i] != 0.0f) continue;  // boundary particles may sit outside
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

float WcsphConfig::c0() const {
  if (sound_speed > 0.0f) return sound_speed;
  return scenario == "dam-break" ? 20.0f * std::sqrt(gravity * height())
                                 : 10.0f * std::sqrt(2.0f * gravity * height());
}

float WcsphConfig::viscosity() const {
  const float h = h_over_dx * dx();
  return rest_density * viscosity_alpha * h * c0() / 20.0f;
}

float WcsphConfig::run_time() const {
  if (end_time > 0.0f) return end_time;
  if (scenario == "dam-break") return 3.3f / std::sqrt(2.0f * gravity / column_width);
  return 0.5f;
}

double TimeStepLimits::dt() const {
  return std::min({cfl, force, viscous});
}

TimeStepLimits wcsph_time_step(float h, float c0, float max_speed, float max_acceleration,
                               float rest_density, float viscosity, float coefficient) {
  const double inf = std::numeric_limits<double>::infinity();
  const double hm = 0.5 * h;  // Monaghan's smoothing length: our h is the support radius 2 h_M
  TimeStepLimits t;
  t.cfl = coefficient * hm / (double{c0} + max_speed);
  t.force = max_acceleration > 0.0f ? coefficient * std::sqrt(hm / max_acceleration) : inf;
  t.viscous = viscosity > 0.0f ? 0.5 * coefficient * hm * hm * rest_density / viscosity : inf;
  return t;
}

namespace {

// Sums over the cubic lattice of spacing dx around a point of it, in double: poly6 = sum_j
// W_poly6(r, h) (the point included), gradient = sum_j x_j^2 |grad W_spiky(r, h)| / r (the
// point excluded; times the particle volume it is 1 in the continuum).
struct LatticeSums {
  double poly6 = 0, gradient = 0;
};
LatticeSums lattice_sums(double dx, double h) {
  const double pi = 3.14159265358979323846;
  const double poly6 = 315.0 / (64.0 * pi * std::pow(h, 9));
  const double spiky = 45.0 / (pi * std::pow(h, 6));
  const int reach = static_cast<int>(std::ceil(h / dx));
  LatticeSums s;
  for (int i = -reach; i <= reach; ++i)
    for (int j = -reach; j <= reach; ++j)
      for (int k = -reach; k <= reach; ++k) {
        const double r2 = dx * dx * (i * i + j * j + k * k);
        if (r2 >= h * h) continue;
        s.poly6 += poly6 * std::pow(h * h - r2, 3);
        if (r2 > 0) {
          const double r = std::sqrt(r2);
          s.gradient += dx * dx * i * i * spiky * (h - r) * (h - r) / r;
        }
      }
  return s;
}

float parse_float(const std::string& key, const std::string& value) {
  try {
    std::size_t used = 0;
    const float f = std::stof(value, &used);
    if (used != value.size()) throw std::invalid_argument(value);
    return f;
  } catch (const std::exception&) {
    throw Error(ErrorCode::invalid_argument, "scenario key '" + key + "': not a number: " + value);
  }
}

std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t\r");
  if (b == std::string::npos) return "";
  const auto e = s.find_last_not_of(" \t\r");
  return s.substr(b, e - b + 1);
}

}  // namespace

void set_wcsph_key(WcsphConfig& c, const std::string& key, const std::string& value) {
  const auto number = [&] { return parse_float(key, value); };
  const auto integer = [&] {
    const float f = number();
    if (f != std::floor(f))
      throw Error(ErrorCode::invalid_argument, "scenario key '" + key + "': not an integer");
    return static_cast<int>(f);
  };
  if (key == "scenario") {
    require(value == "dam-break" || value == "hydrostatic", ErrorCode::invalid_argument,
            "scenario must be dam-break or hydrostatic, not " + value);
    c.scenario = value;
  } else if (key == "column_width") {
    c.column_width = number();
  } else if (key == "column_height") {
    c.column_height = number();
  } else if (key == "tank_length") {
    c.tank_length = number();
  } else if (key == "resolution") {
    c.resolution = integer();
  } else if (key == "dx") {
    const float dx = number();
    require(dx > 0.0f, ErrorCode::invalid_argument, "dx must be > 0");
    c.resolution = static_cast<int>(std::lround(c.column_width / dx));
  } else if (key == "h_over_dx") {
    c.h_over_dx = number();
  } else if (key == "sound_speed" || key == "c0") {
    c.sound_speed = number();
  } else if (key == "cfl") {
    c.cfl = number();
  } else if (key == "viscosity_alpha") {
    c.viscosity_alpha = number();
  } else if (key == "rest_density") {
    c.rest_density = number();
  } else if (key == "gravity") {
    c.gravity = number();
  } else if (key == "boundary_layers") {
    c.boundary_layers = integer();
  } else if (key == "negative_pressure") {
    require(value == "clamp" || value == "keep", ErrorCode::invalid_argument,
            "negative_pressure must be clamp or keep, not " + value);
    c.clamp_negative_pressure = value == "clamp";
  } else if (key == "end_time") {
    c.end_time = number();
  } else if (key == "damping" || key == "damping_time") {
    // Negative values are the struct's "the scenario's default"; given explicitly they are a
    // mistake, not a request for the default.
    const float f = number();
    require(std::isfinite(f) && f >= 0.0f, ErrorCode::invalid_argument,
            key + " must be a finite number >= 0 (" +
                (key == "damping" ? "1/s; 0: no damping" : "s; 0: no damping") + "), got " + value);
    (key == "damping" ? c.damping : c.damping_time) = f;
  } else {
    throw Error(ErrorCode::invalid_argument, "unknown scenario key '" + key + "'");
  }
}

WcsphConfig read_wcsph_config(const std::string& path, WcsphConfig base) {
  io::LineReader in(path);  // a directory, /dev/zero or a binary file: Error(io)
  std::string line;
  while (in.next(line)) {
    const std::size_t number = in.number();
    const auto hash = line.find('#');
    if (hash != std::string::npos) line.resize(hash);
    line = trim(line);
    if (line.empty()) continue;
    const auto eq = line.find('=');
    if (eq == std::string::npos)
      throw Error(ErrorCode::invalid_argument, path + ":" + std::to_string(number) +
                                                   ": expected key = value, found '" +
                                                   io::printable(line) + "'");
    try {
      set_wcsph_key(base, trim(line.substr(0, eq)), trim(line.substr(eq + 1)));
    } catch (const Error& e) {
      throw Error(ErrorCode::invalid_argument,
                  path + ":" + std::to_string(number) + ": " + e.what());
    }
  }
  return base;
}

namespace {

// Why the sizes of `c` cannot be run in float (empty when they can): the particle mass
// rest_density / sum W (about rest_density dx^3) must be a normal float, and the density and
// force kernels at the support h must pass validate_kernel_range with the solver's options.
std::string wcsph_unfit(const WcsphConfig& c) {
  const double dx = c.dx();
  const float h = c.h_over_dx * c.dx();
  if (!positive_finite(static_cast<float>(dx)) || !positive_finite(h))
    return "dx or h is not a finite float > 0";
  const LatticeSums sums = lattice_sums(dx, h);
  const double mass = c.rest_density / sums.poly6;
  if (!(mass >= std::numeric_limits<float>::min() && mass <= std::numeric_limits<float>::max())) {
    char text[120];
    std::snprintf(text, sizeof text,
                  "the particle mass (about rest_density x dx^3) = %g kg is "
                  "not a normal float",
                  mass);
    return text;
  }
  SphParameters p;
  p.particle_mass = static_cast<float>(mass);
  p.gradient_correction = static_cast<float>(sums.poly6 / sums.gradient);
  p.viscosity = c.viscosity();
  p.weakly_compressible = true;
  try {
    validate_kernel_range(Kernel::sph_density, density_pass_options(p), h);
    validate_kernel_range(Kernel::sph_force, force_pass_options(p), h);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

// The column widths (at c's other sizes) that wcsph_unfit accepts, [lo, hi], found in log
// space (the quantities are powers of dx): {0, 0} when no decade from 1e-30 to 1e30 works.
std::pair<double, double> wcsph_width_range(WcsphConfig c) {
  const auto fits = [&c](double width) {
    c.column_width = static_cast<float>(width);
    return wcsph_unfit(c).empty();
  };
  double good = 0;
  for (int e = -30; e <= 30 && good == 0; ++e)
    if (fits(std::pow(10.0, e))) good = std::pow(10.0, e);
  if (good == 0) return {0, 0};
  const auto edge = [&](double bad) {  // the boundary between `good` and `bad`, bisected
    double in = std::log(good), out = std::log(bad);
    for (int k = 0; k < 40; ++k) {
      const double mid = 0.5 * (in + out);
      (fits(std::exp(mid)) ? in : out) = mid;
    }
    return std::exp(in);
  };
  return {edge(1e-40), edge(1e38)};
}

}  // namespace

SphScenario wcsph_scenario(const WcsphConfig& c) {
  require(c.scenario == "dam-break" || c.scenario == "hydrostatic", ErrorCode::invalid_argument,
          "scenario must be dam-break or hydrostatic");
  require(positive_finite(c.column_width) && c.resolution >= 2 && c.resolution <= 1000,
          ErrorCode::invalid_argument, "need column_width > 0 and resolution in [2, 1000]");
  require(c.h_over_dx >= 1.0f && c.h_over_dx <= 4.0f, ErrorCode::invalid_argument,
          "h_over_dx must be in [1, 4]");
  require(c.boundary_layers >= 1 && c.boundary_layers <= 8, ErrorCode::invalid_argument,
          "boundary_layers must be in [1, 8]");
  require(positive_finite(c.cfl) && c.cfl <= 1.0f, ErrorCode::invalid_argument,
          "cfl must be in (0, 1]");
  require(std::isfinite(c.viscosity_alpha) && c.viscosity_alpha >= 0.0f,
          ErrorCode::invalid_argument, "viscosity_alpha must be >= 0");
  require(positive_finite(c.rest_density), ErrorCode::invalid_argument,
          "rest_density must be finite and > 0");
  require(positive_finite(c.gravity), ErrorCode::invalid_argument,
          "gravity must be finite and > 0");
  require(
      positive_finite(c.height()) && positive_finite(c.length()) && c.length() >= c.column_width,
      ErrorCode::invalid_argument,
      "column_height must be > 0 and tank_length at least column_width");
  require(std::isfinite(c.sound_speed) && c.sound_speed >= 0.0f, ErrorCode::invalid_argument,
          "c0 must be finite and >= 0 (0: the default)");
  require(std::isfinite(c.end_time) && c.end_time >= 0.0f, ErrorCode::invalid_argument,
          "end_time must be finite and >= 0 (0: the default)");

  if (const std::string why = wcsph_unfit(c); !why.empty()) {
    // Name the scenario's own sizes (the caller never set particle_mass or a kernel's factor).
    const auto [lo, hi] = wcsph_width_range(c);
    char text[300];
    std::snprintf(text, sizeof text,
                  "scenario %s: column_width = %g m at resolution %d (particle spacing dx = %g m, "
                  "support h = %g m) cannot be simulated in float: ",
                  c.scenario.c_str(), static_cast<double>(c.column_width), c.resolution,
                  static_cast<double>(c.dx()), static_cast<double>(c.h_over_dx * c.dx()));
    char range[160];
    std::snprintf(range, sizeof range,
                  "; column_width must be in [%.3g, %.3g] m at this resolution and these sizes", lo,
                  hi);
    throw Error(ErrorCode::invalid_argument,
                text + why + (hi > 0 ? std::string(range) : std::string()));
  }
  const double dx = c.dx();
  const float h = c.h_over_dx * c.dx();
  const float c0 = c.c0();
  {
    // Sized in double before any int conversion or allocation, and refused when it cannot fit.
    const double L = c.boundary_layers, n = c.resolution;
    const double ny = std::round(c.height() / dx), nx_tank = std::round(c.length() / dx);
    const double fluid = n * ny * n;
    const double boundary = (nx_tank + 2 * L) * (ny + 2 + L) * (n + 2 * L) - nx_tank * (ny + 2) * n;
    char what[200];
    std::snprintf(what, sizeof what, "scenario %s: %.4g particles (%.4g fluid + %.4g boundary)",
                  c.scenario.c_str(), fluid + boundary, fluid, boundary);
    require_host_memory((fluid + boundary) * run_bytes_per_particle, what);
    require(fluid + boundary < 2e9, ErrorCode::invalid_argument,
            std::string(what) + ": more than 2e9, too many for one run");
  }
  const int nx_fluid = c.resolution;
  const int ny_fluid = static_cast<int>(std::lround(c.height() / dx));
  const int nz = c.resolution;
  const int nx_tank = static_cast<int>(std::lround(c.length() / dx));
  const int ny_tank = ny_fluid + 2;  // walls: 2 dx above the fluid's top, open top
  const int layers = c.boundary_layers;

  SphScenario s;
  s.name = c.scenario;
  SphParameters& p = s.params;
  p.rest_density = c.rest_density;
  const LatticeSums sums = lattice_sums(dx, h);
  p.particle_mass = static_cast<float>(c.rest_density / sums.poly6);
  p.gradient_correction = static_cast<float>(sums.poly6 / sums.gradient);  // 1 / (V sum)
  p.smoothing_length = h;
  p.stiffness = 1.0f;  // unused by Tait
  p.viscosity = c.viscosity();
  p.gravity = {0.0f, -c.gravity, 0.0f};
  p.weakly_compressible = true;
  p.sound_speed = c0;
  p.clamp_negative_pressure = c.clamp_negative_pressure;
  const bool settle = c.scenario == "hydrostatic";
  p.damping = c.damping >= 0.0f ? c.damping : (settle ? c0 / c.height() : 0.0f);
  p.damping_time = c.damping_time >= 0.0f ? c.damping_time : (settle ? 0.3f : 0.0f);
  require(std::isfinite(p.damping) && std::isfinite(p.damping_time), ErrorCode::invalid_argument,
          "damping and damping_time must be finite");
  const TimeStepLimits limits =
      wcsph_time_step(h, c0, 0.1f * c0, 100.0f * c.gravity, c.rest_density, p.viscosity, c.cfl);
  p.dt = static_cast<float>(limits.dt());
  // Safety planes through the innermost boundary layer; stiffness (c0 / h_M)^2 (a period of
  // 2 pi h_M / c0, resolved by the CFL step).
  const float hm = 0.5f * h;
  p.wall_stiffness = (c0 / hm) * (c0 / hm);
  const float half = 0.5f * static_cast<float>(dx);
  const float lx = static_cast<float>(nx_tank * dx), lz = static_cast<float>(nz * dx);
  const float ceiling = 100.0f * static_cast<float>(ny_tank * dx);
  p.walls = {{{{0.0f, 1.0f, 0.0f}, half},
              {{0.0f, -1.0f, 0.0f}, ceiling},
              {{1.0f, 0.0f, 0.0f}, half},
              {{-1.0f, 0.0f, 0.0f}, lx + half},
              {{0.0f, 0.0f, 1.0f}, half},
              {{0.0f, 0.0f, -1.0f}, lz + half}}};

  const auto add = [&](int i, int j, int k, float fixed) {
    s.position.push_back(static_cast<float>((i + 0.5) * dx));
    s.position.push_back(static_cast<float>((j + 0.5) * dx));
    s.position.push_back(static_cast<float>((k + 0.5) * dx));
    s.fixed.push_back(fixed);
  };
  // Fluid first (x fastest, then y, then z), then the boundary.
  for (int k = 0; k < nz; ++k)
    for (int j = 0; j < ny_fluid; ++j)
      for (int i = 0; i < nx_fluid; ++i) add(i, j, k, 0.0f);
  for (int k = -layers; k < nz + layers; ++k)
    for (int j = -layers; j < ny_tank; ++j)
      for (int i = -layers; i < nx_tank + layers; ++i) {
        const bool inside = i >= 0 && i < nx_tank && j >= 0 && k >= 0 && k < nz;
        if (!inside) add(i, j, k, 1.0f);
      }
  s.velocity.assign(s.position.size(), 0.0f);
  const double frames = std::ceil(c.run_time() / double{p.dt});
  require(frames < 1e8, ErrorCode::invalid_argument, "end_time / dt: too many steps");
  s.frames = static_cast<int>(frames);
  s.image_frame = 0;
  return s;
}

}  // namespace raycut::sph
