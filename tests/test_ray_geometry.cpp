// CPU emulation of the ray-tracing methods: the same rays, primitives and filters as the OptiX
// programs (src/geometry/ray_geometry.hpp), with hits decided analytically in double the way
// OptiX reports them (spheres: the entry only, nothing from inside; triangles: a crossing of the
// closed triangle; boxes: the origin inside). Proves on CI, without a GPU, that every in-range
// pair is kept exactly once and no other pair is kept, on every input family.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <string>
#include <vector>

#include "geometry/ray_geometry.hpp"
#include "raycut/generators.hpp"
#include "raycut/predicate.hpp"

namespace {

namespace geo = raycut::detail::geometry;
using raycut::PointCloud;

struct Ray {
  double o[3], dir[3], length;
};

// Entry of a ray that starts outside the sphere, within the segment.
bool sphere_entry(const Ray& ray, const float q[3], double r) {
  double oc[3], b = 0, c = -r * r;
  for (int a = 0; a < 3; ++a) {
    oc[a] = ray.o[a] - q[a];
    b += oc[a] * ray.dir[a];
    c += oc[a] * oc[a];
  }
  if (c <= 0) return false;  // inside or on: OptiX reports nothing
  const double disc = b * b - c;
  if (disc < 0) return false;
  const double t = -b - std::sqrt(disc);
  return t >= 0 && t <= ray.length;
}

// A +x ray against a triangle in a plane x = const (closed triangle).
bool crosses_triangle(const Ray& ray, const float v[9]) {
  const double t = v[0] - ray.o[0];
  if (t < 0 || t > ray.length) return false;
  const double py = ray.o[1], pz = ray.o[2];
  auto edge = [&](int a, int b) {
    return (v[3 * b + 1] - v[3 * a + 1]) * (pz - v[3 * a + 2]) -
           (v[3 * b + 2] - v[3 * a + 2]) * (py - v[3 * a + 1]);
  };
  const double e0 = edge(0, 1), e1 = edge(1, 2), e2 = edge(2, 0);
  return (e0 >= 0 && e1 >= 0 && e2 >= 0) || (e0 <= 0 && e1 <= 0 && e2 <= 0);
}

float largest_magnitude(const PointCloud& cloud) {
  float m = 0;
  for (float x : cloud.xyz) m = std::max(m, std::fabs(x));
  return m;
}

enum class Method { spheres, triangles, aabb };

// How many times the method's filter keeps (i, j), for every j, by emulated traversal.
std::vector<int> kept(Method method, const PointCloud& cloud, std::size_t i, float e) {
  const float cutoff = cloud.cutoff, c2 = raycut::squared_cutoff(cutoff);
  const std::size_t n = cloud.size();
  const float* x = &cloud.xyz[3 * i];
  std::vector<int> count(n, 0);
  auto pair = [&](std::size_t j, float d[3]) {
    for (int a = 0; a < 3; ++a) d[a] = cloud.xyz[3 * j + a] - x[a];
    return j != i && raycut::in_range(raycut::squared_distance(d[0], d[1], d[2]), c2);
  };
  if (method == Method::spheres) {
    const geo::SphereRays rays = geo::sphere_rays(cutoff, e);
    for (int k = 0; k < 3; ++k) {
      Ray ray{{x[0], x[1], x[2]}, {0, 0, 0}, rays.length};
      ray.dir[k] = 1;
      ray.o[k] = x[k] - rays.back * 1.0f;  // as the raygen computes it, in float
      ray.o[k] = static_cast<float>(ray.o[k]);
      for (std::size_t j = 0; j < n; ++j) {
        float d[3];
        if (sphere_entry(ray, &cloud.xyz[3 * j], rays.radius) && pair(j, d) &&
            geo::sphere_axis(d[0], d[1], d[2]) == k)
          ++count[j];
      }
    }
  } else if (method == Method::triangles) {
    for (int corner = 0; corner < 4; ++corner) {
      float o[3];
      geo::corner_ray_origin(x[0], x[1], x[2], corner, cutoff, e, o);
      const Ray ray{{o[0], o[1], o[2]}, {1, 0, 0}, geo::corner_ray_length(cutoff, e)};
      for (std::size_t j = 0; j < n; ++j) {
        for (int face = 0; face < 2; ++face) {
          float v[9], d[3];
          const float* q = &cloud.xyz[3 * j];
          geo::face_triangle(q[0], q[1], q[2], face, cutoff, e, v);
          if (crosses_triangle(ray, v) && pair(j, d) && geo::kept_corner(d[1], d[2]) == corner &&
              geo::kept_face(d[0]) == face)
            ++count[j];
        }
      }
    }
  } else {
    const float half = geo::aabb_half_width(cutoff, e);
    for (std::size_t j = 0; j < n; ++j) {
      const float* q = &cloud.xyz[3 * j];
      bool inside = true;
      for (int a = 0; a < 3; ++a) inside &= q[a] - half <= x[a] && x[a] <= q[a] + half;
      float d[3];
      if (inside && pair(j, d)) ++count[j];
    }
  }
  return count;
}

std::string method_name(Method m) {
  return m == Method::spheres ? "spheres" : m == Method::triangles ? "triangles" : "aabb";
}

void PrintTo(Method m, std::ostream* os) {
  *os << method_name(m);
}

class RayGeometry : public ::testing::TestWithParam<std::tuple<Method, std::string, float>> {};

TEST_P(RayGeometry, KeepsEveryInRangePairExactlyOnce) {
  const auto& [method, family, cutoff] = GetParam();
  const PointCloud cloud = raycut::make_family(family, 700, cutoff, 11);
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
  if (cloud.size() > 2 && family.find("-k1") == std::string::npos) {
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
