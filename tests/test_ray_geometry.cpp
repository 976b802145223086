// CPU emulation of the ray-tracing methods: the same rays, primitives and filters as the OptiX
// programs (src/geometry/ray_geometry.hpp), with hits decided analytically in double the way
// OptiX reports them (spheres: the entry only, nothing from inside; triangles: a crossing of the
// closed triangle; boxes: the origin inside). Proves on CI, without a GPU, that every in-range
// pair is kept exactly once and no other pair is kept, on every input family.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <tuple>
#include <vector>

#include "ray_emulation.hpp"
#include "raycut/predicate.hpp"
#include "raycut/tools/generators.hpp"

namespace {

namespace geo = raycut::detail::geometry;
using raycut::PointCloud;
using raycut::emulation::kept;
using raycut::emulation::largest_magnitude;
using raycut::emulation::Method;
using raycut::emulation::method_name;

class RayGeometry : public ::testing::TestWithParam<std::tuple<Method, std::string, float>> {};

TEST_P(RayGeometry, KeepsEveryInRangePairExactlyOnce) {
  const auto& [method, family, family_cutoff] = GetParam();
  const PointCloud cloud = raycut::make_family(family, 700, family_cutoff, 11);
  const float cutoff = cloud.cutoff;  // tiny-scale and huge-scale rescale it with the cloud
  const float e = geo::margin(cutoff, largest_magnitude(cloud));
  const float c2 = raycut::squared_cutoff(cutoff);
  std::size_t pairs = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const std::vector<int> count = kept(method, cloud, i, e);
    for (std::size_t j = 0; j < cloud.size(); ++j) {
      float d[3];
      for (int a = 0; a < 3; ++a) d[a] = cloud.xyz[3 * j + a] - cloud.xyz[3 * i + a];
      const bool in = j != i && raycut::in_range(raycut::squared_distance(d[0], d[1], d[2]), c2);
      ASSERT_EQ(count[j], in ? 1 : 0) << "target " << i << ", source " << j << ", d = (" << d[0]
                                      << ", " << d[1] << ", " << d[2] << ")";
      pairs += in;
    }
  }
  // Lattices of spacing C have no pair in range (all at or beyond the cutoff).
  // So has the rod (10^6 C long: ~0.0014 neighbours per point at 700 points).
  if (cloud.size() > 2 && family.find("-k1") == std::string::npos && family != "rod-1e6") {
    EXPECT_GT(pairs, 0u);
  }
}

INSTANTIATE_TEST_SUITE_P(
    Families, RayGeometry,
    ::testing::Combine(::testing::Values(Method::spheres, Method::triangles, Method::aabb),
                       ::testing::ValuesIn(raycut::family_names()), ::testing::Values(1.0f, 0.37f)),
    [](const auto& info) {
      std::string name = method_name(std::get<0>(info.param)) + "_" + std::get<1>(info.param) +
                         (std::get<2>(info.param) == 1.0f ? "_c100" : "_c37");
      for (char& c : name)
        if (c == '-') c = '_';
      return name;
    });

}  // namespace

// ---- the local frame and the valid domain (docs/methods.md, "Valid domain of each ray-tracing
// method") -------------------------------------------------------------------------------------
namespace {

using raycut::emulation::Arithmetic;

geo::Shape shape_of(Method m) {
  return m == Method::spheres     ? geo::Shape::spheres
         : m == Method::triangles ? geo::Shape::triangles
                                  : geo::Shape::aabb;
}

// Every (i, j) kept exactly as often as the shared predicate says (1 or 0); returns the number of
// (target, source) pairs that were kept wrongly (missed, repeated or spurious).
std::size_t wrong_pairs(Method method, const PointCloud& cloud, float e, Arithmetic arithmetic) {
  const float c2 = raycut::squared_cutoff(cloud.cutoff);
  std::size_t wrong = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const std::vector<int> count = kept(method, cloud, i, e, arithmetic);
    for (std::size_t j = 0; j < cloud.size(); ++j) {
      float d[3];
      for (int a = 0; a < 3; ++a) d[a] = cloud.xyz[3 * j + a] - cloud.xyz[3 * i + a];
      const bool in = j != i && raycut::in_range(raycut::squared_distance(d[0], d[1], d[2]), c2);
      wrong += count[j] != (in ? 1 : 0);
    }
  }
  return wrong;
}

// What RayTracingMethod::build does on the host: box, exact shift, local magnitude S.
struct Frame {
  float lo[3], hi[3], shift[3];
  double magnitude;
};
Frame frame_of(const PointCloud& cloud) {
  Frame f{};
  for (int a = 0; a < 3; ++a) f.lo[a] = f.hi[a] = cloud.xyz[a];
  for (std::size_t i = 0; i < cloud.size(); ++i)
    for (int a = 0; a < 3; ++a) {
      f.lo[a] = std::min(f.lo[a], cloud.xyz[3 * i + a]);
      f.hi[a] = std::max(f.hi[a], cloud.xyz[3 * i + a]);
    }
  for (int a = 0; a < 3; ++a) f.shift[a] = geo::exact_shift(f.lo[a], f.hi[a]);
  f.magnitude = geo::local_magnitude(f.lo, f.hi, f.shift);
  return f;
}
PointCloud shifted(const PointCloud& cloud, const Frame& f) {
  PointCloud out = cloud;
  for (std::size_t k = 0; k < out.xyz.size(); ++k) out.xyz[k] -= f.shift[k % 3];
  return out;
}

PointCloud offset_cloud(double by, std::size_t n = 500) {
  PointCloud cloud = raycut::make_family("uniform", n, 1.0f, 5);
  for (float& v : cloud.xyz) v = static_cast<float>(v + by);
  return cloud;
}

// Groups of particles `apart` cutoffs from each other: a compact cloud at 0 and its copy at
// (apart, apart/2, 0).
PointCloud far_groups(double apart, std::size_t n = 400) {
  PointCloud cloud = raycut::make_family("uniform", n / 2, 1.0f, 9);
  const std::vector<float> base = cloud.xyz;
  for (std::size_t k = 0; k < base.size(); ++k)
    cloud.xyz.push_back(static_cast<float>(base[k] + (k % 3 == 0   ? apart
                                                      : k % 3 == 1 ? apart / 2
                                                                   : 0)));
  return cloud;
}

TEST(RayDomain, ExactShiftLeavesEveryCoordinateDifferenceExact) {
  // Property: whenever shift_is_exact says so, x - c is exact for floats across the range.
  std::uint64_t state = 12345;
  auto next = [&] {
    state = state * 6364136223846793005ULL + 1442695040888963407ULL;
    return static_cast<double>(state >> 11) * 0x1p-53;
  };
  int shifted_axes = 0;
  for (int trial = 0; trial < 2000; ++trial) {
    const double centre =
        std::ldexp(next() < 0.5 ? -1.0 : 1.0, static_cast<int>(next() * 80) - 40) * (1 + next());
    const double width =
        std::fabs(centre) * std::ldexp(1.0, -static_cast<int>(next() * 30)) * next();
    const float lo = static_cast<float>(centre - width), hi = static_cast<float>(centre + width);
    const float c = geo::exact_shift(lo, hi);
    if (c == 0) continue;
    ++shifted_axes;
    ASSERT_TRUE(lo <= c && c <= hi);
    for (int k = 0; k < 50; ++k) {
      const float x = k == 0   ? lo
                      : k == 1 ? hi
                               : static_cast<float>(lo + (double{hi} - lo) * next());
      ASSERT_EQ(double{x - c}, double{x} - double{c}) << "x = " << x << ", c = " << c;
    }
  }
  EXPECT_GT(shifted_axes, 1000);
  // A range that holds 0 is not shifted; neither is one reaching close to 0.
  EXPECT_EQ(geo::exact_shift(-1.0f, 5.0f), 0.0f);
  EXPECT_EQ(geo::exact_shift(1e-3f, 1e5f), 0.0f);
  EXPECT_NE(geo::exact_shift(1e5f, 1e5f + 30), 0.0f);
}

// Far offsets of a compact cloud: in the local frame the scene is the cloud's own
// half-width, the pair vectors are the caller's bit for bit, and the emulated geometry (float hit
// tests) keeps every pair once. Without the shift, 1e7 is beyond every geometry's bound.
TEST(RayDomain, FarOffsetCloudIsCompactInTheLocalFrame) {
  for (double by : {1e3, 1e5, 1e7, -1e7, 3e9}) {
    const PointCloud cloud = offset_cloud(by);
    const Frame f = frame_of(cloud);
    const PointCloud local = shifted(cloud, f);
    for (int a = 0; a < 3; ++a) EXPECT_NE(f.shift[a], 0.0f) << "offset " << by;
    EXPECT_LT(f.magnitude, 0.51 * (f.hi[0] - f.lo[0]) + 1) << "offset " << by;
    for (std::size_t i = 0; i < cloud.size(); i += 7)
      for (std::size_t j = 0; j < cloud.size(); ++j)
        for (int a = 0; a < 3; ++a)
          ASSERT_EQ(cloud.xyz[3 * j + a] - cloud.xyz[3 * i + a],
                    local.xyz[3 * j + a] - local.xyz[3 * i + a]);
    const float e = geo::margin(cloud.cutoff, static_cast<float>(f.magnitude));
    for (Method m : {Method::spheres, Method::triangles, Method::aabb}) {
      EXPECT_LE(f.magnitude / cloud.cutoff, geo::max_scene_cutoffs(shape_of(m)));
      EXPECT_EQ(wrong_pairs(m, local, e, Arithmetic::float32), 0u)
          << method_name(m) << ", offset " << by;
    }
  }
  EXPECT_GT(1e7, geo::max_scene_cutoffs(geo::Shape::aabb));
}

// The bound of each geometry leaves our own arithmetic exact: a cluster far out at 0.99 S_max
// (coordinates there resolve C to 2^-7 .. 2^-6), a particle at -0.99 S_max so that the box holds
// 0 and no shift applies, margin at its largest; float hit tests keep every pair once.
TEST(RayDomain, FloatGeometryIsExactUpToEachBound) {
  for (Method m : {Method::spheres, Method::triangles, Method::aabb}) {
    const double bound = geo::max_scene_cutoffs(shape_of(m));
    PointCloud cloud = offset_cloud(0.99 * bound - 10, 400);
    for (int a = 0; a < 3; ++a) cloud.xyz.push_back(static_cast<float>(-0.99 * bound));
    const Frame f = frame_of(cloud);
    ASSERT_LE(f.magnitude / cloud.cutoff, bound);
    const float e = geo::margin(cloud.cutoff, static_cast<float>(f.magnitude));
    EXPECT_EQ(wrong_pairs(m, cloud, e, Arithmetic::float32), 0u) << method_name(m);
    EXPECT_EQ(wrong_pairs(m, cloud, e, Arithmetic::exact), 0u) << method_name(m);
  }
}

// Groups astronomically far apart: the margin follows the largest coordinate, and at
// 1e30 cutoffs the sphere's r^2 and the triangles' edge products overflow float: float hit tests
// lose the pairs (the exact ones do not). The domain check refuses every geometry there, and
// already at 1e6 cutoffs.
TEST(RayDomain, FarGroupsAreRefusedWhereFloatGeometryFails) {
  const PointCloud astronomic = far_groups(1e30);
  const float e = geo::margin(1.0f, largest_magnitude(astronomic));
  EXPECT_GT(wrong_pairs(Method::spheres, astronomic, e, Arithmetic::float32), 0u);
  EXPECT_GT(wrong_pairs(Method::triangles, astronomic, e, Arithmetic::float32), 0u);
  EXPECT_EQ(wrong_pairs(Method::spheres, astronomic, e, Arithmetic::exact), 0u);
  for (double apart : {1e6, 1e12, 1e30}) {
    const Frame f = frame_of(far_groups(apart));
    for (Method m : {Method::spheres, Method::triangles, Method::aabb})
      EXPECT_GT(f.magnitude, geo::max_scene_cutoffs(shape_of(m)))
          << method_name(m) << ", " << apart;
  }
}

TEST(RayDomain, TheMarginGrowsEachPrimitiveByAtMostAQuarterWithinTheBound) {
  const float c = 0.37f;
  const float at_spheres =
      geo::margin(c, static_cast<float>(c * geo::max_scene_cutoffs(geo::Shape::spheres)));
  EXPECT_LE(at_spheres, 0.81649658f * c / 4 * 1.0001f);
  const float at_triangles =
      geo::margin(c, static_cast<float>(c * geo::max_scene_cutoffs(geo::Shape::triangles)));
  EXPECT_LE(2 * at_triangles, c / 8 * 1.0001f);
  const float at_boxes =
      geo::margin(c, static_cast<float>(c * geo::max_scene_cutoffs(geo::Shape::aabb)));
  EXPECT_LE(at_boxes, c / 4 * 1.0001f);
}

}  // namespace
