// CPU emulation of ray traversal, shared by the tests: rays, analytic hit tests in double on the
// float primitives (reported the way OptiX reports them: built-in spheres give the entry only and
// nothing to a ray that starts inside; triangles are closed; boxes contain the ray origin), and
// our three ray-tracing methods cast with the geometry of src/geometry/ray_geometry.hpp.
// tests/test_ray_geometry.cpp proves our filters exactly-once with it; tests/test_paper_filters.cpp
// runs it next to its emulation of the paper's published filters.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <ostream>
#include <string>
#include <vector>

#include "geometry/ray_geometry.hpp"
#include "raycut/predicate.hpp"
#include "raycut/tools/generators.hpp"

namespace raycut::emulation {

namespace geo = raycut::detail::geometry;

struct Ray {
  double o[3], dir[3], length;
};

// Entry of a ray that starts outside the sphere, within the segment.
inline bool sphere_entry(const Ray& ray, const float q[3], double r) {
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

// Is (py, pz) in the closed triangle v (x, y, z per vertex), projected on the yz plane?
inline bool in_closed_triangle_yz(double py, double pz, const float v[9]) {
  auto edge = [&](int a, int b) {
    return (v[3 * b + 1] - v[3 * a + 1]) * (pz - v[3 * a + 2]) -
           (v[3 * b + 2] - v[3 * a + 2]) * (py - v[3 * a + 1]);
  };
  const double e0 = edge(0, 1), e1 = edge(1, 2), e2 = edge(2, 0);
  return (e0 >= 0 && e1 >= 0 && e2 >= 0) || (e0 <= 0 && e1 <= 0 && e2 <= 0);
}

// A +x ray against a triangle in a plane x = const (closed triangle).
inline bool crosses_triangle(const Ray& ray, const float v[9]) {
  const double t = v[0] - ray.o[0];
  if (t < 0 || t > ray.length) return false;
  return in_closed_triangle_yz(ray.o[1], ray.o[2], v);
}

// The same three hit tests evaluated in float, in a textbook order of operations (OptiX's own are
// undocumented): where the geometry leaves float's range (squares of radii or triangle edges
// beyond FLT_MAX, cancellation), these lose hits that the exact tests keep. Box tests are
// comparisons of floats, exact either way.
inline bool sphere_entry_float(const Ray& ray, const float q[3], float r) {
  float oc[3], b = 0, c = 0;
  for (int a = 0; a < 3; ++a) {
    oc[a] = static_cast<float>(ray.o[a]) - q[a];
    b += oc[a] * static_cast<float>(ray.dir[a]);
    c += oc[a] * oc[a];
  }
  c -= r * r;
  if (!(c > 0)) return false;  // inside or on (or NaN): nothing reported
  const float disc = b * b - c;
  if (!(disc >= 0)) return false;
  const float t = -b - std::sqrt(disc);
  return t >= 0 && t <= static_cast<float>(ray.length);
}

inline bool crosses_triangle_float(const Ray& ray, const float v[9]) {
  const float t = v[0] - static_cast<float>(ray.o[0]);
  if (!(t >= 0 && t <= static_cast<float>(ray.length))) return false;
  const float py = static_cast<float>(ray.o[1]), pz = static_cast<float>(ray.o[2]);
  auto edge = [&](int a, int b) {
    const float ab_y = v[3 * b + 1] - v[3 * a + 1], ab_z = v[3 * b + 2] - v[3 * a + 2];
    const float ap_y = py - v[3 * a + 1], ap_z = pz - v[3 * a + 2];
    const float first = ab_y * ap_z, second = ab_z * ap_y;
    return first - second;
  };
  const float e0 = edge(0, 1), e1 = edge(1, 2), e2 = edge(2, 0);
  return (e0 >= 0 && e1 >= 0 && e2 >= 0) || (e0 <= 0 && e1 <= 0 && e2 <= 0);
}

// How the emulation decides hits: exactly (double, on the float primitives) or in float.
enum class Arithmetic { exact, float32 };

inline float largest_magnitude(const PointCloud& cloud) {
  float m = 0;
  for (float x : cloud.xyz) m = std::max(m, std::fabs(x));
  return m;
}

enum class Method { spheres, triangles, aabb };

// How many times our method's filter keeps (i, j), for every j, by emulated traversal.
inline std::vector<int> kept(Method method, const PointCloud& cloud, std::size_t i, float e,
                             Arithmetic arithmetic = Arithmetic::exact) {
  const bool exact = arithmetic == Arithmetic::exact;
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
        const float* q = &cloud.xyz[3 * j];
        const bool hit =
            exact ? sphere_entry(ray, q, rays.radius) : sphere_entry_float(ray, q, rays.radius);
        if (hit && pair(j, d) && geo::sphere_axis(d[0], d[1], d[2]) == k) ++count[j];
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
          const bool hit = exact ? crosses_triangle(ray, v) : crosses_triangle_float(ray, v);
          if (hit && pair(j, d) && geo::kept_corner(d[1], d[2]) == corner &&
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

inline std::string method_name(Method m) {
  return m == Method::spheres ? "spheres" : m == Method::triangles ? "triangles" : "aabb";
}

inline void PrintTo(Method m, std::ostream* os) {
  *os << method_name(m);
}

}  // namespace raycut::emulation
