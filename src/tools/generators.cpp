// The benchmark suites (docs/benchmarks.md, "Protocol") and the test families (docs/methods.md,
// "Test inputs"). Everything is drawn from detail::SplitMix64, so a (name, n, cutoff,
// seed) gives the same bits on every platform and for every thread count.
#include "raycut/tools/generators.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numbers>
#include <thread>

#include "raycut/error.hpp"
#include "tools/random.hpp"

namespace raycut {
namespace {

using detail::SplitMix64;
using detail::stream_for;

// Runs body(i) for i in [0, n) on a few threads. Each point draws from its own counter-based
// stream, so the split does not change the result.
template <class Body>
void parallel_for(std::size_t n, const Body& body) {
  constexpr std::size_t min_items_per_thread = std::size_t{1} << 16;
  const std::size_t hardware = std::max(1u, std::thread::hardware_concurrency());
  const std::size_t threads = std::min(hardware, n / min_items_per_thread + 1);
  if (threads <= 1) {
    for (std::size_t i = 0; i < n; ++i) body(i);
    return;
  }
  std::vector<std::thread> workers;
  workers.reserve(threads);
  for (std::size_t t = 0; t < threads; ++t) {
    workers.emplace_back([&, t] {
      const std::size_t begin = n * t / threads, end = n * (t + 1) / threads;
      for (std::size_t i = begin; i < end; ++i) body(i);
    });
  }
  for (auto& worker : workers) worker.join();
}

void require_positive(int value, const char* what) {
  if (value < 1) {
    throw Error(ErrorCode::invalid_argument,
                std::string(what) + " must be >= 1, got " + std::to_string(value));
  }
}

std::string join(const std::vector<std::string>& words) {
  std::string joined;
  for (const auto& word : words) joined += (joined.empty() ? "" : ", ") + word;
  return joined;
}

// ---- test families -------------------------------------------------------------------------

struct Point {
  double x, y, z;
};

// Appends a point, rounding each coordinate to float once.
void push(std::vector<float>& xyz, double x, double y, double z) {
  xyz.push_back(static_cast<float>(x));
  xyz.push_back(static_cast<float>(y));
  xyz.push_back(static_cast<float>(z));
}

// Side of a cube in which n uniform points have about 25 neighbours within the cutoff:
// (n / side^3) * (4/3) pi C^3 = 25. Never below C, so tiny n stay within range of each other.
double uniform_side(std::size_t n, double cutoff) {
  const double volume_per_cutoff3 = static_cast<double>(n) * (4.0 / 3.0 * std::numbers::pi) / 25.0;
  return std::max(cutoff, cutoff * std::cbrt(volume_per_cutoff3));
}

Point uniform_in_cube(SplitMix64& rng, double side) {
  const double x = rng.uniform_double() * side;
  const double y = rng.uniform_double() * side;
  const double z = rng.uniform_double() * side;
  return {x, y, z};
}

Point unit_direction(SplitMix64& rng) {
  const double z = 1.0 - 2.0 * rng.uniform_double();
  const double angle = 2.0 * std::numbers::pi * rng.uniform_double();
  const double r = std::sqrt(std::max(0.0, 1.0 - z * z));
  return {r * std::cos(angle), r * std::sin(angle), z};
}

// A power of two about cutoff / 4096. Coordinates that are integer multiples of it (and below
// 2^24 of it, about 2000 cutoffs) are exact in float, and so are their differences: the axis and
// diagonal families build on this to get exact ties.
double exact_quantum(double cutoff) {
  return std::ldexp(1.0, std::ilogb(cutoff) - 12);
}
double snap(double value, double quantum) {
  return std::round(value / quantum) * quantum;
}

std::vector<float> uniform_cloud(std::size_t n, double cutoff, std::uint64_t seed) {
  SplitMix64 rng = stream_for(seed, 0);
  const double side = uniform_side(n, cutoff);
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const Point p = uniform_in_cube(rng, side);
    push(xyz, p.x, p.y, p.z);
  }
  return xyz;
}

std::vector<float> sphere_surface(std::size_t n, double cutoff, std::uint64_t seed) {
  // n C^2 / (4 R^2) = 20 neighbours on average.
  const double radius = std::max(cutoff, cutoff * std::sqrt(static_cast<double>(n) / 80.0));
  const double centre = radius + cutoff;
  SplitMix64 rng = stream_for(seed, 1);
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const Point d = unit_direction(rng);
    push(xyz, centre + radius * d.x, centre + radius * d.y, centre + radius * d.z);
  }
  return xyz;
}

// m^3 points, m = round(cbrt(n)); coordinates float(i) * s (+ s/2), the same expression on every
// axis so that equal index differences give equal float differences wherever they are exact.
std::vector<float> lattice(std::size_t n, float cutoff, int per_cutoff, bool shifted) {
  if (n == 0) return {};
  const auto side = static_cast<std::size_t>(
      std::max<long long>(1, std::llround(std::cbrt(static_cast<double>(n)))));
  const float spacing = cutoff / static_cast<float>(per_cutoff);
  const float shift = shifted ? spacing * 0.5f : 0.0f;
  auto coordinate = [&](std::size_t i) { return static_cast<float>(i) * spacing + shift; };
  std::vector<float> xyz;
  xyz.reserve(3 * side * side * side);
  for (std::size_t k = 0; k < side; ++k) {
    for (std::size_t j = 0; j < side; ++j) {
      for (std::size_t i = 0; i < side; ++i) {
        xyz.push_back(coordinate(i));
        xyz.push_back(coordinate(j));
        xyz.push_back(coordinate(k));
      }
    }
  }
  return xyz;
}

// Sites uniform at the density of "uniform"; each repeated 1..6 times as exact copies.
std::vector<float> coincident(std::size_t n, double cutoff, std::uint64_t seed) {
  SplitMix64 rng = stream_for(seed, 10);
  const double side = uniform_side(n, cutoff);
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  std::size_t count = 0;
  while (count < n) {
    const Point site = uniform_in_cube(rng, side);
    const std::size_t copies = std::min<std::size_t>(1 + rng.next() % 6, n - count);
    for (std::size_t c = 0; c < copies; ++c) push(xyz, site.x, site.y, site.z);
    count += copies;
  }
  return xyz;
}

// Pairs at distances C * 10^(-7 + 4u), i.e. 1e-7 C to 1e-3 C. Where float cannot hold the offset
// (it is below half an ulp of the site) the partner moves one ulp instead, so every pair stays
// distinct: these are the pairs that absolute self-hit thresholds wrongly drop.
std::vector<float> near_coincident(std::size_t n, double cutoff, std::uint64_t seed) {
  SplitMix64 rng = stream_for(seed, 11);
  const double side = uniform_side(n, cutoff);
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  for (std::size_t pair = 0; pair < n / 2; ++pair) {
    const Point p = uniform_in_cube(rng, side);
    const float site[3] = {static_cast<float>(p.x), static_cast<float>(p.y),
                           static_cast<float>(p.z)};
    const double distance = cutoff * std::pow(10.0, -7.0 + 4.0 * rng.uniform_double());
    const Point d = unit_direction(rng);
    const double offset[3] = {distance * d.x, distance * d.y, distance * d.z};
    float partner[3];
    for (int k = 0; k < 3; ++k) partner[k] = static_cast<float>(site[k] + offset[k]);
    if (partner[0] == site[0] && partner[1] == site[1] && partner[2] == site[2]) {
      int largest = 0;
      for (int k = 1; k < 3; ++k) {
        if (std::abs(offset[k]) > std::abs(offset[largest])) largest = k;
      }
      const float towards = offset[largest] < 0 ? -std::numeric_limits<float>::infinity()
                                                : std::numeric_limits<float>::infinity();
      partner[largest] = std::nextafter(site[largest], towards);
    }
    xyz.insert(xyz.end(), site, site + 3);
    xyz.insert(xyz.end(), partner, partner + 3);
  }
  if (n % 2 == 1) {
    const Point p = uniform_in_cube(rng, side);
    push(xyz, p.x, p.y, p.z);
  }
  return xyz;
}

// Bundles of 4 parallel lines (axis x, y, z in turn), at perpendicular offsets (0,0), (h,0),
// (0,h), (h,h) with h ~ C/2: lines share one coordinate exactly and lie within C of each other.
// 24 points per line, spacing ~C/3; every 4th bundle uses spacing ~C/2, which is exactly C/2
// when C is a power of two (pairs two steps apart are then exactly at the cutoff). All
// coordinates are multiples of exact_quantum, so equal steps give exactly equal differences.
std::vector<float> axis_aligned(std::size_t n, double cutoff, std::uint64_t seed) {
  constexpr std::size_t points_per_line = 24;
  SplitMix64 rng = stream_for(seed, 12);
  const double quantum = exact_quantum(cutoff);
  const double side = uniform_side(n, cutoff);
  const double half = snap(cutoff / 2, quantum);
  const double third = snap(cutoff / 3, quantum);
  const double offsets[4][2] = {{0, 0}, {half, 0}, {0, half}, {half, half}};
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  std::size_t count = 0;
  for (std::size_t bundle = 0; count < n; ++bundle) {
    const int axis = static_cast<int>(bundle % 3);
    const double spacing = bundle % 4 == 3 ? half : third;
    const Point p = uniform_in_cube(rng, side);
    const double origin[3] = {snap(p.x, quantum), snap(p.y, quantum), snap(p.z, quantum)};
    for (int line = 0; line < 4 && count < n; ++line) {
      for (std::size_t t = 0; t < points_per_line && count < n; ++t, ++count) {
        double point[3] = {origin[0], origin[1], origin[2]};
        point[axis] += static_cast<double>(t) * spacing;
        point[(axis + 1) % 3] += offsets[line][0];
        point[(axis + 2) % 3] += offsets[line][1];
        push(xyz, point[0], point[1], point[2]);
      }
    }
  }
  return xyz;
}

// Stars: a centre point plus the 4 body diagonals through it, 16 points each at centre +
// t*s*(+-1,+-1,+-1), t = +-1..+-8, 3D spacing ~C/4. s and the centres are multiples of
// exact_quantum, so every coordinate is exact and |dx| = |dy| = |dz| holds exactly in float for
// two points of one diagonal.
std::vector<float> diagonal(std::size_t n, double cutoff, std::uint64_t seed) {
  constexpr int steps = 8;
  constexpr int signs[4][3] = {{1, 1, 1}, {1, 1, -1}, {1, -1, 1}, {-1, 1, 1}};
  SplitMix64 rng = stream_for(seed, 13);
  const double quantum = exact_quantum(cutoff);
  const double side = uniform_side(n, cutoff);
  const double step = snap(cutoff / (4.0 * std::numbers::sqrt3), quantum);
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  std::size_t count = 0;
  while (count < n) {
    const Point p = uniform_in_cube(rng, side);
    const double centre[3] = {snap(p.x, quantum), snap(p.y, quantum), snap(p.z, quantum)};
    push(xyz, centre[0], centre[1], centre[2]);
    ++count;
    for (int d = 0; d < 4; ++d) {
      for (int t = -steps; t <= steps && count < n; ++t) {
        if (t == 0) continue;
        const double along = t * step;
        push(xyz, centre[0] + signs[d][0] * along, centre[1] + signs[d][1] * along,
             centre[2] + signs[d][2] * along);
        ++count;
      }
    }
  }
  return xyz;
}

// Three Gaussian clusters (n - 1 points, round robin) and, last, one point 1e5 C away from the
// first cluster along the (1,1,1) diagonal. sigma = 2C at 1000 points per cluster (about 30
// neighbours at a centre, 12 on average) and scales as cbrt of the cluster size, so the density
// is the same for every n.
std::vector<float> gaussian_outlier(std::size_t n, double cutoff, std::uint64_t seed) {
  if (n == 0) return {};
  SplitMix64 rng = stream_for(seed, 14);
  const std::size_t clustered = n - 1;
  const double per_cluster = static_cast<double>(clustered) / 3.0;
  const double sigma = 2.0 * cutoff * std::cbrt(per_cluster / 1000.0);
  const Point centres[3] = {{0, 0, 0}, {8 * sigma, 0, 0}, {4 * sigma, 7 * sigma, 0}};
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  for (std::size_t i = 0; i < clustered; ++i) {
    const Point& c = centres[i % 3];
    const double x = c.x + sigma * rng.normal();
    const double y = c.y + sigma * rng.normal();
    const double z = c.z + sigma * rng.normal();
    push(xyz, x, y, z);
  }
  const double far = 1e5 * cutoff / std::numbers::sqrt3;
  push(xyz, far, far, far);
  return xyz;
}

// K of "<prefix>K" for K in 1..4, else 0.
int lattice_divisions(std::string_view name, std::string_view prefix) {
  if (name.size() != prefix.size() + 1 || !name.starts_with(prefix)) return 0;
  const char k = name.back();
  return k >= '1' && k <= '4' ? k - '0' : 0;
}

std::vector<float> offset(std::vector<float> xyz, float by) {
  for (float& v : xyz) v += by;
  return xyz;
}

// n points in a cube of side C/4: its diagonal is sqrt(3)/4 C < C, so every pair is in range.
std::vector<float> large_cutoff(std::size_t n, double cutoff, std::uint64_t seed) {
  SplitMix64 rng = stream_for(seed, 17);
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const Point p = uniform_in_cube(rng, cutoff / 4);
    push(xyz, p.x, p.y, p.z);
  }
  return xyz;
}

// ---- extreme scales (docs/limits.md) -----------------------------------------------------------

// The uniform cloud times a power of two (exact: the same float mantissas, so the same pairs).
std::vector<float> scaled(std::vector<float> xyz, int exponent) {
  for (float& v : xyz) v = std::ldexp(v, exponent);
  return xyz;
}

// Spacing of floats at `value` (> 0).
double float_ulp(double value) {
  const auto f = static_cast<float>(value);
  return static_cast<double>(std::nextafter(f, std::numeric_limits<float>::infinity())) - f;
}

// Uniform points offset by `by` on every coordinate, rounded to float once. The cube's side is
// the uniform family's, or cbrt(n / 4) float spacings at `by` where that is wider, so that on
// average at most ~4 points fall on one float site (beyond that the float grid is coarser than
// the cutoff and every point of a site is coincident with the others).
std::vector<float> far_offset(std::size_t n, double cutoff, double by, std::uint64_t seed) {
  SplitMix64 rng = stream_for(seed, 20);
  const double side =
      std::max(uniform_side(n, cutoff), std::cbrt(static_cast<double>(n) / 4.0) * float_ulp(by));
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const Point p = uniform_in_cube(rng, side);
    push(xyz, by + p.x, by + p.y, by + p.z);
  }
  return xyz;
}

// Multivariate Cauchy (Student t, 1 degree of freedom): a g / |w|, g standard normal in 3D, w
// standard normal, scale a such that about 25 points lie within C of the centre. Its tail is
// heavy: the farthest of n points is ~n a away (|w| is floored at 1e-12).
std::vector<float> cauchy(std::size_t n, double cutoff, std::uint64_t seed) {
  SplitMix64 rng = stream_for(seed, 21);
  // Density at the centre n / (pi^2 a^3); times (4/3) pi C^3 = 25 neighbours.
  const double a = cutoff * std::cbrt(static_cast<double>(n) * (4.0 / 3.0 * std::numbers::pi) /
                                      (25.0 * std::numbers::pi * std::numbers::pi));
  const double scale = std::max(a, cutoff);
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = rng.normal(), y = rng.normal(), z = rng.normal();
    const double w = std::max(std::fabs(rng.normal()), 1e-12);
    push(xyz, scale * x / w, scale * y / w, scale * z / w);
  }
  return xyz;
}

// Side of a square in which n points have about 20 neighbours: n pi C^2 / side^2 = 20.
double sheet_side(std::size_t n, double cutoff) {
  return std::max(cutoff, cutoff * std::sqrt(static_cast<double>(n) * std::numbers::pi / 20.0));
}

// A square sheet of n points, side sheet_side, normal to `axis`, at `height` + [0, thickness)
// along it.
void push_sheet(std::vector<float>& xyz, SplitMix64& rng, std::size_t n, double cutoff, int axis,
                double height, double thickness) {
  const double side = sheet_side(n, cutoff);
  for (std::size_t i = 0; i < n; ++i) {
    double p[3];
    p[(axis + 1) % 3] = rng.uniform_double() * side;
    p[(axis + 2) % 3] = rng.uniform_double() * side;
    p[axis] = height + rng.uniform_double() * thickness;
    push(xyz, p[0], p[1], p[2]);
  }
}

// Four groups of ~n/4 points: a uniform cube at the origin and three square sheets, at
// x = 1e10 C, y = 1e20 C and z = 1e30 C (at most 1e36, so that C up to 1e18 stays finite). A
// sheet keeps its far coordinate exactly equal on all its points, and its other two near 0,
// where floats are fine: far groups without the loss of resolution a far cube would have.
std::vector<float> groups_far(std::size_t n, double cutoff, std::uint64_t seed) {
  SplitMix64 rng = stream_for(seed, 22);
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  const std::size_t cube = n - 3 * (n / 4);
  const double side = uniform_side(cube, cutoff);
  for (std::size_t i = 0; i < cube; ++i) {
    const Point p = uniform_in_cube(rng, side);
    push(xyz, p.x, p.y, p.z);
  }
  for (int g = 1; g <= 3; ++g) {
    const double far = std::min(std::pow(10.0, 10.0 * g) * cutoff, 1e36);
    push_sheet(xyz, rng, n / 4, cutoff, g - 1, far, 0.0);
  }
  return xyz;
}

// Uniform in a box C x C x 10^6 C.
std::vector<float> rod(std::size_t n, double cutoff, std::uint64_t seed) {
  SplitMix64 rng = stream_for(seed, 24);
  std::vector<float> xyz;
  xyz.reserve(3 * n);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = rng.uniform_double() * cutoff, y = rng.uniform_double() * cutoff;
    push(xyz, x, y, rng.uniform_double() * 1e6 * cutoff);
  }
  return xyz;
}

}  // namespace

// ---- benchmark suites ----------------------------------------------------------------------

std::size_t suite_size(int param, int p) {
  require_positive(param, "suite parameter (beta or alpha)");
  require_positive(p, "p");
  const auto side = static_cast<std::size_t>(param);
  return static_cast<std::size_t>(p) * side * side * side;
}

PointCloud uniform_suite(int beta, int p, std::uint64_t seed) {
  const std::size_t n = suite_size(beta, p);
  PointCloud cloud;
  cloud.name = "uniform beta=" + std::to_string(beta) + " p=" + std::to_string(p);
  cloud.cutoff = 1.0f / static_cast<float>(beta);
  cloud.xyz.resize(3 * n);
  float* xyz = cloud.xyz.data();
  parallel_for(n, [&](std::size_t i) {
    SplitMix64 rng = stream_for(seed, i);
    xyz[3 * i + 0] = rng.uniform_float();
    xyz[3 * i + 1] = rng.uniform_float();
    xyz[3 * i + 2] = rng.uniform_float();
  });
  return cloud;
}

PointCloud surface_suite(int alpha, int p, std::uint64_t seed) {
  const std::size_t n = suite_size(alpha, p);
  PointCloud cloud;
  cloud.name = "surface alpha=" + std::to_string(alpha) + " p=" + std::to_string(p);
  const double cos_cutoff = 1.0 - 2.0 * 9.0 * p / static_cast<double>(n);
  cloud.cutoff = static_cast<float>(std::acos(std::clamp(cos_cutoff, -1.0, 1.0)));
  cloud.xyz.resize(3 * n);
  float* xyz = cloud.xyz.data();
  parallel_for(n, [&](std::size_t i) {
    SplitMix64 rng = stream_for(seed, i);
    const double theta = 2.0 * std::numbers::pi * rng.uniform_double();
    const double phi = std::acos(1.0 - 2.0 * rng.uniform_double());
    xyz[3 * i + 0] = static_cast<float>(std::sin(phi) * std::cos(theta) + 1.0);
    xyz[3 * i + 1] = static_cast<float>(std::sin(phi) * std::sin(theta) + 1.0);
    xyz[3 * i + 2] = static_cast<float>(std::cos(phi) + 1.0);
  });
  return cloud;
}

// ---- test families -------------------------------------------------------------------------

std::vector<std::string> family_names() {
  return {"uniform",
          "sphere-surface",
          "lattice-k1",
          "lattice-k2",
          "lattice-k3",
          "lattice-k4",
          "lattice-shifted-k1",
          "lattice-shifted-k2",
          "lattice-shifted-k3",
          "lattice-shifted-k4",
          "coincident",
          "near-coincident",
          "axis-aligned",
          "diagonal",
          "gaussian-outlier",
          "offset-1e3",
          "offset-1e5",
          "large-cutoff",
          "tiny-scale",
          "huge-scale",
          "offset-1e7",
          "offset-1e15",
          "cauchy",
          "groups-far",
          "sheet-flat",
          "sheet-thin",
          "rod-1e6"};
}

PointCloud make_family(std::string_view name, std::size_t n, float cutoff, std::uint64_t seed) {
  if (!std::isfinite(cutoff) || !(cutoff > 0)) {
    throw Error(ErrorCode::invalid_argument,
                "cutoff must be finite and > 0, got " + std::to_string(cutoff));
  }
  const double c = cutoff;
  PointCloud cloud;
  cloud.name = std::string(name);
  cloud.cutoff = cutoff;
  if (name == "uniform") {
    cloud.xyz = uniform_cloud(n, c, seed);
  } else if (name == "sphere-surface") {
    cloud.xyz = sphere_surface(n, c, seed);
  } else if (const int k = lattice_divisions(name, "lattice-k"); k > 0) {
    cloud.xyz = lattice(n, cutoff, k, /*shifted=*/false);
  } else if (const int k = lattice_divisions(name, "lattice-shifted-k"); k > 0) {
    cloud.xyz = lattice(n, cutoff, k, /*shifted=*/true);
  } else if (name == "coincident") {
    cloud.xyz = coincident(n, c, seed);
  } else if (name == "near-coincident") {
    cloud.xyz = near_coincident(n, c, seed);
  } else if (name == "axis-aligned") {
    cloud.xyz = axis_aligned(n, c, seed);
  } else if (name == "diagonal") {
    cloud.xyz = diagonal(n, c, seed);
  } else if (name == "gaussian-outlier") {
    cloud.xyz = gaussian_outlier(n, c, seed);
  } else if (name == "offset-1e3") {
    cloud.xyz = offset(uniform_cloud(n, c, seed), 1e3f);
  } else if (name == "offset-1e5") {
    cloud.xyz = offset(uniform_cloud(n, c, seed), 1e5f);
  } else if (name == "large-cutoff") {
    cloud.xyz = large_cutoff(n, c, seed);
  } else if (name == "tiny-scale" || name == "huge-scale") {
    const int exponent = name == "tiny-scale" ? -50 : 50;
    cloud.xyz = scaled(uniform_cloud(n, c, seed), exponent);
    cloud.cutoff = std::ldexp(cutoff, exponent);
    if (!std::isfinite(cloud.cutoff) || !(cloud.cutoff > 0)) {
      throw Error(ErrorCode::invalid_argument, std::string(name) + " scales the cutoff by 2^" +
                                                   std::to_string(exponent) + ": " +
                                                   std::to_string(cutoff) + " leaves float range");
    }
  } else if (name == "offset-1e7") {
    cloud.xyz = far_offset(n, c, 1e7, seed);
  } else if (name == "offset-1e15") {
    cloud.xyz = far_offset(n, c, 1e15, seed);
  } else if (name == "cauchy") {
    cloud.xyz = cauchy(n, c, seed);
  } else if (name == "groups-far") {
    cloud.xyz = groups_far(n, c, seed);
  } else if (name == "sheet-flat" || name == "sheet-thin") {
    SplitMix64 rng = stream_for(seed, 23);
    cloud.xyz.reserve(3 * n);
    push_sheet(cloud.xyz, rng, n, c, 2, 0.0, name == "sheet-flat" ? 0.0 : 1e-6 * c);
  } else if (name == "rod-1e6") {
    cloud.xyz = rod(n, c, seed);
  } else {
    throw Error(ErrorCode::invalid_argument, "unknown input family '" + std::string(name) +
                                                 "' (known: " + join(family_names()) + ")");
  }
  return cloud;
}

}  // namespace raycut
