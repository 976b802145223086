// CPU emulation of the ray-tracing methods: the same rays, primitives and filters as the OptiX
// programs (src/geometry/ray_geometry.hpp), with hits decided analytically in double the way
// OptiX reports them (spheres: the entry only, nothing from inside; triangles: a crossing of the
// closed triangle; boxes: the origin inside). Proves on CI, without a GPU, that every in-range
// pair is kept exactly once and no other pair is kept, on every input family.
#include <gtest/gtest.h>

#include <string>
#include <tuple>
#include <vector>

#include "ray_emulation.hpp"
#include "raycut/generators.hpp"
#include "raycut/predicate.hpp"

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
