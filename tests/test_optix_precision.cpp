// The OptiX methods on inputs whose coordinates span many orders of magnitude
// beyond the cutoff. For every OptiX method available here and every input class (a compact cloud
// far from the origin, groups of particles far apart, heavy-tailed clouds with far outliers):
// either the method's CSR neighbour list equals a double-precision oracle (pairs within a relative
// 1e-5 of the cutoff may go either way), or build() refuses with Error(unsupported) naming the
// method, the scene's extent in cutoffs and the supported bound. Which one is not left to chance:
// the test computes the scene's local magnitude S the way build() does (src/geometry/
// ray_geometry.hpp: exact shift, then largest |x - origin|) and requires a run within the bound
// and a refusal beyond it (docs/methods.md, "Valid domain of each ray-tracing method").
// Runs on a GPU with OptiX (ctest -R OptixPrecision); skipped with the reason elsewhere.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <map>
#include <memory>
#include <numeric>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include "geometry/ray_geometry.hpp"
#include "raycut/engine.hpp"
#include "raycut/error.hpp"
#include "raycut/tools/generators.hpp"

namespace {

namespace geo = raycut::detail::geometry;
using raycut::PointCloud;

// ---- inputs ------------------------------------------------------------------------------------

constexpr float kCutoff = 0.25f;

void push(std::vector<float>& xyz, double x, double y, double z) {
  xyz.push_back(static_cast<float>(x));
  xyz.push_back(static_cast<float>(y));
  xyz.push_back(static_cast<float>(z));
}

// n points uniform in a cube of side `side` cutoffs at `corner` (cutoff units): ~30 neighbours
// each when side = (n * 4.19 / 30)^(1/3).
void uniform_cube(std::vector<float>& xyz, std::size_t n, double side, const double corner[3],
                  std::mt19937_64& rng) {
  std::uniform_real_distribution<double> u(0.0, 1.0);
  for (std::size_t i = 0; i < n; ++i) {
    const double x = corner[0] + side * u(rng), y = corner[1] + side * u(rng),
                 z = corner[2] + side * u(rng);
    push(xyz, x * kCutoff, y * kCutoff, z * kCutoff);
  }
}

double side_for(std::size_t n) {
  return std::cbrt(static_cast<double>(n) * 4.18879 / 30.0);
}

// A compact cloud of 20,000 points offset by `by` cutoffs (on x only when `x_only`).
PointCloud far_offset(double by, bool x_only = false) {
  std::mt19937_64 rng(1);
  PointCloud cloud;
  cloud.cutoff = kCutoff;
  const double corner[3] = {by, x_only ? -0.5 * side_for(20000) : by,
                            x_only ? -0.5 * side_for(20000) : by};
  uniform_cube(cloud.xyz, 20000, side_for(20000), corner, rng);
  return cloud;
}

// Four clusters of 1,500 points, `apart` cutoffs from each other: at 0, apart x, apart y and
// apart (x + y + z). Beyond ~1e7 cutoffs a cluster far out collapses to a few float positions
// (coincident particles, all in range of each other).
PointCloud far_groups(double apart) {
  std::mt19937_64 rng(2);
  PointCloud cloud;
  cloud.cutoff = kCutoff;
  const double corners[4][3] = {{0, 0, 0}, {apart, 0, 0}, {0, apart, 0}, {apart, apart, apart}};
  for (const auto& corner : corners) uniform_cube(cloud.xyz, 1500, side_for(1500), corner, rng);
  return cloud;
}

// Clusters at every scale at once: 1e6, 1e12, 1e18, 1e24, 1e30 cutoffs from the origin.
PointCloud groups_at_every_scale() {
  std::mt19937_64 rng(3);
  PointCloud cloud;
  cloud.cutoff = kCutoff;
  for (double at : {0.0, 1e6, 1e12, 1e18, 1e24, 1e30}) {
    const double corner[3] = {at, -at, 0.5 * at};
    uniform_cube(cloud.xyz, 1000, side_for(1000), corner, rng);
  }
  return cloud;
}

// 100,000 points, each coordinate Cauchy of scale 7 cutoffs (~20 neighbours in the core). With
// `clip` > 0 the coordinates are clipped to +-clip cutoffs and 5 outliers are added at distance
// `outliers` cutoffs on the axes; with clip = 0 the raw tail (its largest coordinate is
// typically ~1e5-1e6 cutoffs).
PointCloud heavy_tailed(double clip, double outliers, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::cauchy_distribution<double> cauchy(0.0, 7.0);
  PointCloud cloud;
  cloud.cutoff = kCutoff;
  const std::size_t n = outliers > 0 ? 100000 - 5 : 100000;
  auto draw = [&] {
    const double v = cauchy(rng);
    return clip > 0 ? std::clamp(v, -clip, clip) : v;
  };
  for (std::size_t i = 0; i < n; ++i) {
    const double x = draw(), y = draw(), z = draw();
    push(cloud.xyz, x * kCutoff, y * kCutoff, z * kCutoff);
  }
  // The outliers on the axes (+x, -y, +z, -x, +y), so that S = `outliers` cutoffs exactly.
  for (int k = 0; outliers > 0 && k < 5; ++k) {
    double d[3] = {0, 0, 0};
    d[k % 3] = k % 2 == 0 ? outliers : -outliers;
    push(cloud.xyz, d[0] * kCutoff, d[1] * kCutoff, d[2] * kCutoff);
  }
  return cloud;
}

struct Case {
  std::string name;
  PointCloud (*make)();
};

const std::vector<Case>& cases() {
  static const std::vector<Case> all = {
      {"offset_1e3", [] { return far_offset(1e3); }},
      {"offset_1e5", [] { return far_offset(1e5); }},
      {"offset_1e7", [] { return far_offset(1e7); }},
      {"offset_minus_1e7", [] { return far_offset(-1e7); }},
      {"offset_1e7_x_only", [] { return far_offset(1e7, true); }},
      {"groups_1e4", [] { return far_groups(1e4); }},
      {"groups_1e6", [] { return far_groups(1e6); }},
      {"groups_1e9", [] { return far_groups(1e9); }},
      {"groups_1e12", [] { return far_groups(1e12); }},
      {"groups_1e18", [] { return far_groups(1e18); }},
      {"groups_1e24", [] { return far_groups(1e24); }},
      {"groups_1e30", [] { return far_groups(1e30); }},
      {"groups_every_scale", [] { return groups_at_every_scale(); }},
      {"cauchy_raw", [] { return heavy_tailed(0, 0, 4); }},
      {"cauchy_outliers_1e3", [] { return heavy_tailed(700, 1e3, 8); }},
      {"cauchy_outliers_1e4", [] { return heavy_tailed(700, 1e4, 9); }},
      {"cauchy_outliers_3e4", [] { return heavy_tailed(700, 3e4, 5); }},
      {"cauchy_outliers_6e4", [] { return heavy_tailed(700, 6e4, 10); }},
      {"cauchy_outliers_1p5e5", [] { return heavy_tailed(700, 1.5e5, 6); }},
      {"cauchy_outliers_1e7", [] { return heavy_tailed(700, 1e7, 7); }},
  };
  return all;
}

// ---- the oracle: double precision, not the shared predicate
// --------------------------------------

// Per target, the sources surely in range (|d| < (1 - 1e-5) C, in double) and those in the band
// ((1 +- 1e-5) C), either way allowed. Sweep over x-sorted particles.
struct Oracle {
  std::vector<std::vector<std::uint32_t>> sure, band;
};

Oracle oracle_of(const PointCloud& cloud) {
  const std::size_t n = cloud.size();
  const double c = cloud.cutoff, inner = c * (1 - 1e-5), outer = c * (1 + 1e-5);
  std::vector<std::uint32_t> order(n);
  std::iota(order.begin(), order.end(), 0u);
  const float* x = cloud.xyz.data();
  std::sort(order.begin(), order.end(), [&](auto a, auto b) { return x[3 * a] < x[3 * b]; });
  Oracle o;
  o.sure.resize(n);
  o.band.resize(n);
  for (std::size_t s = 0; s < n; ++s) {
    const std::uint32_t i = order[s];
    for (std::size_t t = s + 1; t < n; ++t) {
      const std::uint32_t j = order[t];
      const double dx = double{x[3 * j]} - x[3 * i];
      if (dx >= outer) break;
      const double dy = double{x[3 * j + 1]} - x[3 * i + 1],
                   dz = double{x[3 * j + 2]} - x[3 * i + 2];
      const double r = std::sqrt(dx * dx + dy * dy + dz * dz);
      if (r < inner) {
        o.sure[i].push_back(j);
        o.sure[j].push_back(i);
      } else if (r < outer) {
        o.band[i].push_back(j);
        o.band[j].push_back(i);
      }
    }
  }
  for (auto& row : o.sure) std::sort(row.begin(), row.end());
  for (auto& row : o.band) std::sort(row.begin(), row.end());
  return o;
}

struct Input {
  PointCloud cloud;
  std::unique_ptr<Oracle> oracle;  // computed the first time a method runs on the input
  double magnitude = 0;            // S / C as build() computes it
};

Input& input(const Case& c) {
  static std::map<std::string, Input> inputs;
  auto it = inputs.find(c.name);
  if (it == inputs.end()) {
    Input in;
    in.cloud = c.make();
    float lo[3], hi[3], shift[3];
    for (int a = 0; a < 3; ++a) lo[a] = hi[a] = in.cloud.xyz[a];
    for (std::size_t i = 0; i < in.cloud.size(); ++i)
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], in.cloud.xyz[3 * i + a]);
        hi[a] = std::max(hi[a], in.cloud.xyz[3 * i + a]);
      }
    for (int a = 0; a < 3; ++a) shift[a] = geo::exact_shift(lo[a], hi[a]);
    in.magnitude = geo::local_magnitude(lo, hi, shift) / in.cloud.cutoff;
    it = inputs.emplace(c.name, std::move(in)).first;
  }
  return it->second;
}

geo::Shape shape_of(const std::string& method) {
  if (method == "optix-spheres") return geo::Shape::spheres;
  if (method == "optix-triangles") return geo::Shape::triangles;
  return geo::Shape::aabb;
}

// Compares a CSR list with the oracle; returns "" when it matches, else what is wrong.
std::string compare(const raycut::NeighbourList& list, const Oracle& o, const PointCloud& cloud) {
  const std::size_t n = cloud.size();
  if (list.offsets.size() != n + 1) return "offsets has " + std::to_string(list.offsets.size());
  std::size_t bad_targets = 0, missed = 0, spurious = 0, repeated = 0;
  std::ostringstream first;
  for (std::size_t i = 0; i < n; ++i) {
    std::vector<std::uint32_t> row(list.indices.begin() + list.offsets[i],
                                   list.indices.begin() + list.offsets[i + 1]);
    std::sort(row.begin(), row.end());
    std::size_t m = 0, s = 0, r = 0;
    for (std::size_t k = 1; k < row.size(); ++k) r += row[k] == row[k - 1];
    for (std::uint32_t j : o.sure[i]) m += !std::binary_search(row.begin(), row.end(), j);
    for (std::uint32_t j : row)
      s += !std::binary_search(o.sure[i].begin(), o.sure[i].end(), j) &&
           !std::binary_search(o.band[i].begin(), o.band[i].end(), j);
    if (m + s + r > 0) {
      if (bad_targets < 3)
        first << " target " << i << " at (" << cloud.xyz[3 * i] << ", " << cloud.xyz[3 * i + 1]
              << ", " << cloud.xyz[3 * i + 2] << "): " << m << " missed, " << s << " spurious, "
              << r << " repeated of " << o.sure[i].size() << ";";
      ++bad_targets;
      missed += m, spurious += s, repeated += r;
    }
  }
  if (bad_targets == 0) return "";
  return std::to_string(bad_targets) + " of " + std::to_string(n) + " targets wrong (" +
         std::to_string(missed) + " missed, " + std::to_string(spurious) + " spurious, " +
         std::to_string(repeated) + " repeated);" + first.str();
}

// ---- the test ----------------------------------------------------------------------------------

const std::vector<std::string> kMethods = {"optix-spheres", "optix-triangles", "optix-aabb",
                                           "optix-aabb-sorted", "optix-aabb-fused"};

// skin > 0 makes the build refittable (OPTIX_BUILD_FLAG_ALLOW_UPDATE), which may also keep OptiX
// from splitting primitives in its BVH: each case runs both ways, so that a failure of one build
// only points at the builder.
class OptixPrecision : public ::testing::TestWithParam<std::tuple<std::string, std::size_t, bool>> {
};

TEST_P(OptixPrecision, MatchesTheOracleOrRefusesNamingTheBound) {
  const auto& [method, index, refittable] = GetParam();
  for (const raycut::MethodDescription& d : raycut::list_methods())
    if (d.name == method && !d.available) GTEST_SKIP() << method << ": " << d.why_unavailable;
  const Case& c = cases()[index];
  Input& in = input(c);
  const double bound = geo::max_scene_cutoffs(shape_of(method));
  const float skin = refittable ? 0.01f * in.cloud.cutoff : 0.0f;
  const double magnitude = in.magnitude + double{skin} / in.cloud.cutoff;
  char bound_text[64], head[256];
  std::snprintf(bound_text, sizeof bound_text, "%.0f", bound);
  std::snprintf(head, sizeof head,
                "[optix-precision] %s %s%s: S = %.4g cutoffs, bound %s: ", method.c_str(),
                c.name.c_str(), refittable ? " refittable" : "", magnitude, bound_text);

  raycut::Engine engine(method);
  engine.set_update_policy({skin});
  try {
    engine.build({in.cloud.xyz.data(), in.cloud.size(), raycut::MemorySpace::host},
                 in.cloud.cutoff);
  } catch (const raycut::Error& error) {
    const std::string what = error.what();
    std::printf("%srefused: %s\n", head, what.c_str());
    EXPECT_GT(magnitude, bound) << "refused within the bound: " << what;
    EXPECT_EQ(error.code(), raycut::ErrorCode::unsupported) << what;
    EXPECT_NE(what.find(method), std::string::npos) << what;
    EXPECT_NE(what.find(bound_text), std::string::npos) << what;
    EXPECT_NE(what.find("cutoffs"), std::string::npos) << what;
    EXPECT_NE(what.find("grid"), std::string::npos) << what;
    return;
  }
  EXPECT_LE(magnitude, bound) << "built beyond the bound: should have been refused";
  if (!in.oracle) in.oracle = std::make_unique<Oracle>(oracle_of(in.cloud));
  const std::string wrong = compare(engine.neighbours(), *in.oracle, in.cloud);
  std::printf("%s%s\n", head, wrong.empty() ? "exact" : ("WRONG: " + wrong).c_str());
  EXPECT_EQ(wrong, "") << head;
  if (refittable) {  // the refit path, in the same local frame
    engine.update({in.cloud.xyz.data(), in.cloud.size(), raycut::MemorySpace::host});
    EXPECT_TRUE(engine.last_timings().refit) << head;
    EXPECT_EQ(compare(engine.neighbours(), *in.oracle, in.cloud), "") << head << "after refit";
  }
}

INSTANTIATE_TEST_SUITE_P(Classes, OptixPrecision,
                         ::testing::Combine(::testing::ValuesIn(kMethods),
                                            ::testing::Range(std::size_t{0}, cases().size()),
                                            ::testing::Bool()),
                         [](const auto& info) {
                           std::string name = std::get<0>(info.param) + "_" +
                                              cases()[std::get<1>(info.param)].name +
                                              (std::get<2>(info.param) ? "_refittable" : "");
                           for (char& ch : name)
                             if (ch == '-') ch = '_';
                           return name;
                         });

// The oracle and the inputs, checked on the CPU (every build): the cell list, exact at any extent,
// matches the oracle on every input class.
TEST(OptixPrecisionOracle, TheCellListMatchesTheOracle) {
  for (const Case& c : cases()) {
    if (c.name != "offset_1e7" && c.name != "groups_1e30" && c.name != "groups_every_scale" &&
        c.name != "cauchy_outliers_3e4" && c.name != "cauchy_raw")
      continue;
    Input& in = input(c);
    raycut::Engine engine("cell-list");
    engine.build({in.cloud.xyz.data(), in.cloud.size(), raycut::MemorySpace::host},
                 in.cloud.cutoff);
    if (!in.oracle) in.oracle = std::make_unique<Oracle>(oracle_of(in.cloud));
    std::size_t pairs = 0;
    for (const auto& row : in.oracle->sure) pairs += row.size();
    EXPECT_GT(pairs, 3 * in.cloud.size()) << c.name;  // not a trivial comparison
    EXPECT_EQ(compare(engine.neighbours(), *in.oracle, in.cloud), "") << c.name;
  }
}

// The far-offset compact clouds are the case the local origin fixes: no method may refuse them.
TEST(OptixPrecisionDomain, CompactCloudsFarFromTheOriginAreWithinEveryBound) {
  for (const Case& c : cases()) {
    if (c.name.rfind("offset_", 0) != 0) continue;
    for (const std::string& method : kMethods)
      EXPECT_LE(input(c).magnitude, geo::max_scene_cutoffs(shape_of(method)))
          << c.name << ", " << method;
  }
}

}  // namespace
