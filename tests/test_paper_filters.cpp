// The paper's published ray-tracing filters (Algis & Bramas; github berenger-eu/
// particle-interaction-with-optix, SDK/optixMulti{Sphere,Triangle,Custom,SphereAABB}), emulated
// on the CPU from their description in the paper and a reading of the published device
// code (no code copied), next to OUR geometry (src/geometry/ray_geometry.hpp) on the same inputs.
// Each test shows a published filter missing or double counting pairs on an input where the probes
// measured it failing on the H100, and ours keeping every in-range pair exactly once.
// The counts are printed (std::cout) and recorded as test properties for docs/methods.md.
//
// What is modelled, per method (hits decided analytically in double on the float primitives):
// - spheres: radius C sqrt(2/3) + 1e-5; per target 3 axis segments [x - l e_k, x + l e_k],
//   l = C sqrt(2/3); a built-in sphere reports its entry only, nothing to a ray starting inside
//   (measured on the device); optionally every crossing (entry and exit), as a custom intersector
//   would. Filter: |d|^2 < C^2 in float, then the axis of smallest squared distance to the
//   source (d_j^2 + d_k^2), ties to x, then y.
// - double squares: 4 triangles per source (two squares at x -+ C/2 with extents C/2 + 1e-5,
//   each split along its (-,-)-(+,+) diagonal); 4 +x rays per target from (x - C/2, y +- C/2,
//   z +- C/2), t in [FLT_EPSILON, float(C + C 1e-5)]; closed triangles, so a ray through the
//   shared diagonal hits both (Diagonal::both), or, as the device measurements imply, only one
//   (Diagonal::one). Filter: source recovered from the triangle's vertices in float, distance
//   (sqrt, float) in (1e-4, C), then the published ray-choice rule.
// - custom AABB: boxes [q - C, q + C]; a zero-length ray from the target visits every box that
//   contains it, once; the published intersection programs then test |d|^2 < C^2 (unsorted) or
//   <= C^2 (sorted) and exclude self by |d|^2 >= 1e-16, not by index.
#include <gtest/gtest.h>

#include <algorithm>
#include <cctype>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "ray_emulation.hpp"
#include "raycut/predicate.hpp"
#include "raycut/tools/generators.hpp"
#include "tools/random.hpp"

namespace {

namespace geo = raycut::detail::geometry;
using raycut::PointCloud;
using raycut::emulation::in_closed_triangle_yz;
using raycut::emulation::Method;
using raycut::emulation::Ray;

// ---- inputs ------------------------------------------------------------------------------------

PointCloud cloud_of(std::string name, std::vector<float> xyz, float cutoff) {
  PointCloud c;
  c.name = std::move(name);
  c.xyz = std::move(xyz);
  c.cutoff = cutoff;
  return c;
}

// The probes' input: 3,000 uniform random points in [0, 4)^3, C = 1 (our own draw).
PointCloud uniform_box4() {
  raycut::detail::SplitMix64 rng(2024);
  std::vector<float> xyz(3 * 3000);
  for (float& x : xyz) x = 4 * rng.uniform_float();
  return cloud_of("uniform 3000 in 4^3, C=1", std::move(xyz), 1.0f);
}

// m^3 simple cubic lattice, coordinates (float(i) + offset) * spacing.
PointCloud lattice(std::string name, int m, float spacing, float cutoff, float offset = 0) {
  std::vector<float> xyz;
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < m; ++j)
      for (int k = 0; k < m; ++k) {
        xyz.push_back((static_cast<float>(i) + offset) * spacing);
        xyz.push_back((static_cast<float>(j) + offset) * spacing);
        xyz.push_back((static_cast<float>(k) + offset) * spacing);
      }
  return cloud_of(std::move(name), std::move(xyz), cutoff);
}

PointCloud pair(std::string name, float dx, float dy, float dz, float cutoff = 1.0f) {
  return cloud_of(std::move(name), {0, 0, 0, dx, dy, dz}, cutoff);
}

// ---- the paper's published filters, emulated ---------------------------------------------------

constexpr float paper_eps = 1e-5f;  // the paper's absolute widening of spheres and squares

enum class SphereReport { entry_only, entry_and_exit };

// Crossings of the segment with the sphere: the entry only from outside (what OptiX built-in
// spheres report), or every root in the segment (an intersector that reports exits too).
int sphere_hits(const Ray& ray, const float q[3], double r, SphereReport report) {
  if (report == SphereReport::entry_only) return raycut::emulation::sphere_entry(ray, q, r);
  double b = 0, c = -r * r;
  for (int a = 0; a < 3; ++a) {
    const double oc = ray.o[a] - q[a];
    b += oc * ray.dir[a];
    c += oc * oc;
  }
  const double disc = b * b - c;
  if (disc < 0) return 0;
  int hits = 0;
  for (double t : {-b - std::sqrt(disc), -b + std::sqrt(disc)}) hits += t >= 0 && t <= ray.length;
  return hits;
}

// The published sphere any-hit filter, from the target p and the sphere centre q, on ray `axis`.
bool paper_sphere_keeps(const float p[3], const float q[3], float c, int axis) {
  float s[3];
  for (int a = 0; a < 3; ++a) {
    const float d = std::fabs(p[a] - q[a]);
    s[a] = d * d;
  }
  if (!(s[0] + s[1] + s[2] < c * c)) return false;
  const float to_x = s[1] + s[2], to_y = s[0] + s[2], to_z = s[0] + s[1];
  const float m = std::fmin(to_x, std::fmin(to_y, to_z));
  return (m == to_x && axis == 0) || (m == to_y && axis == 1 && m != to_x) ||
         (m == to_z && axis == 2 && m != to_x && m != to_y);
}

std::vector<int> paper_spheres(const PointCloud& cloud, std::size_t i, SphereReport report) {
  const float c = cloud.cutoff;
  const float half_ray = c * 0.81649658092f;
  const float radius = c * 0.81649658092f + paper_eps;
  const float* x = &cloud.xyz[3 * i];
  std::vector<int> count(cloud.size(), 0);
  for (int k = 0; k < 3; ++k) {
    Ray ray{{x[0], x[1], x[2]}, {0, 0, 0}, 2 * half_ray};
    ray.dir[k] = 1;
    ray.o[k] = x[k] - half_ray;  // in float, as the raygen computes it
    for (std::size_t j = 0; j < cloud.size(); ++j) {
      const float* q = &cloud.xyz[3 * j];
      if (std::fabs(q[0] - x[0]) > 2 * c || std::fabs(q[1] - x[1]) > 2 * c ||
          std::fabs(q[2] - x[2]) > 2 * c)
        continue;  // cannot be hit: saves time only
      const int hits = sphere_hits(ray, q, radius, report);
      if (hits > 0 && paper_sphere_keeps(x, q, c, k)) count[j] += hits;
    }
  }
  return count;
}

enum class Diagonal { both, one };

// The paper's 4 triangles of source q: corner k has z sign bit 0, y sign bit 1, x sign bit 2;
// triangles (0,1,3), (0,2,3) on the square at x - C/2 and (4,5,7), (4,6,7) at x + C/2.
void paper_triangles(const float q[3], float c, float v[4][9]) {
  const float up = c / 2 + paper_eps, down = -c / 2 - paper_eps;
  float corner[8][3];
  for (int k = 0; k < 8; ++k) {
    corner[k][0] = q[0] + ((k & 4) ? c / 2 : -c / 2);
    corner[k][1] = q[1] + ((k & 2) ? up : down);
    corner[k][2] = q[2] + ((k & 1) ? up : down);
  }
  const int tri[4][3] = {{0, 1, 3}, {0, 2, 3}, {4, 5, 7}, {4, 6, 7}};
  for (int t = 0; t < 4; ++t)
    for (int a = 0; a < 3; ++a)
      for (int b = 0; b < 3; ++b) v[t][3 * a + b] = corner[tri[t][a]][b];
}

// The published triangle any-hit filter: p the target, v the triangle hit, t its index mod 4.
bool paper_triangle_keeps(const float p[3], const float v[9], int t, float c, int ray) {
  const float qy = (std::max({v[1], v[4], v[7]}) + std::min({v[1], v[4], v[7]})) / 2;
  const float qz = (std::max({v[2], v[5], v[8]}) + std::min({v[2], v[5], v[8]})) / 2;
  const float qx = t < 2 ? v[0] + c / 2 : v[0] - c / 2;
  const float dist =
      std::sqrt((qx - p[0]) * (qx - p[0]) + (qy - p[1]) * (qy - p[1]) + (qz - p[2]) * (qz - p[2]));
  if (!(dist < c && dist > 0.0001)) return false;
  return (p[1] != qy && p[2] != qz) || ((p[2] < qz && ray == 0) || (p[2] > qz && ray == 2)) ||
         ((p[1] < qy && ray == 0) || (p[1] > qy && ray == 1)) || ray == 0;
}

std::vector<int> paper_squares(const PointCloud& cloud, std::size_t i, Diagonal diagonal) {
  const float c = cloud.cutoff, half = c / 2;
  const float tmin = FLT_EPSILON;
  const float tmax = static_cast<float>((2 * half) + (2 * half) * 0.00001);  // as published
  const float* x = &cloud.xyz[3 * i];
  std::vector<int> count(cloud.size(), 0);
  for (int ray = 0; ray < 4; ++ray) {
    const float o[3] = {x[0] - half, x[1] + half * ((ray & 1) ? -1.0f : 1.0f),
                        x[2] + half * ((ray & 2) ? -1.0f : 1.0f)};
    for (std::size_t j = 0; j < cloud.size(); ++j) {
      const float* q = &cloud.xyz[3 * j];
      if (std::fabs(q[0] - x[0]) > 2 * c || std::fabs(q[1] - x[1]) > 2 * c ||
          std::fabs(q[2] - x[2]) > 2 * c)
        continue;  // cannot be hit: saves time only
      float v[4][9];
      paper_triangles(q, c, v);
      for (int t = 0; t < 4; ++t) {
        const double hit_t = static_cast<double>(v[t][0]) - o[0];
        if (hit_t < tmin || hit_t > tmax || !in_closed_triangle_yz(o[1], o[2], v[t])) continue;
        // A hit in both triangles of a square is on their shared diagonal: the second reports it
        // too (closed triangles), or not (one report per diagonal).
        if (diagonal == Diagonal::one && (t & 1) && in_closed_triangle_yz(o[1], o[2], v[t - 1]))
          continue;
        if (paper_triangle_keeps(x, v[t], t, c, ray)) ++count[j];
      }
    }
  }
  return count;
}

enum class PaperAabb { unsorted, sorted, self_by_index };

std::vector<int> paper_aabb(const PointCloud& cloud, std::size_t i, PaperAabb variant) {
  const float c = cloud.cutoff, r2 = c * c;
  const float* x = &cloud.xyz[3 * i];
  std::vector<int> count(cloud.size(), 0);
  for (std::size_t j = 0; j < cloud.size(); ++j) {
    const float* q = &cloud.xyz[3 * j];
    bool inside = true;  // the box [q - C, q + C] contains the ray origin: visited once
    for (int a = 0; a < 3; ++a) inside &= q[a] - c <= x[a] && x[a] <= q[a] + c;
    if (!inside) continue;
    const float o[3] = {x[0] - q[0], x[1] - q[1], x[2] - q[2]};
    const float d2 = o[0] * o[0] + o[1] * o[1] + o[2] * o[2];
    bool keep = false;
    switch (variant) {
      case PaperAabb::unsorted:
        keep = d2 < r2 && d2 >= 1e-16f;
        break;
      case PaperAabb::sorted:
        keep = d2 <= r2 && d2 >= 1e-16f;
        break;
      case PaperAabb::self_by_index:  // THE predicate, on d = source - target
        keep = j != i &&
               raycut::in_range(raycut::squared_distance(q[0] - x[0], q[1] - x[1], q[2] - x[2]),
                                raycut::squared_cutoff(c));
        break;
    }
    count[j] += keep;
  }
  return count;
}

// ---- tallies -----------------------------------------------------------------------------------

struct Tally {
  std::size_t in_range = 0;  // ordered in-range pairs (i != j), by THE predicate
  std::size_t counted = 0;   // pair computations the filter made (sum of the counts)
  std::size_t missed = 0;    // in-range pairs counted 0 times
  std::size_t repeated = 0;  // pairs counted 2 or more times
  std::size_t spurious = 0;  // pairs counted but not in range (or i == j)
  std::size_t self = 0;      // targets that counted themselves
  std::size_t targets_over = 0, targets_under = 0;  // targets whose total count is off
  bool exact() const { return counted == in_range && missed == 0 && repeated == 0 && !spurious; }
};

using Filter = std::function<std::vector<int>(const PointCloud&, std::size_t)>;

Tally tally(const PointCloud& cloud, const Filter& filter) {
  const float c2 = raycut::squared_cutoff(cloud.cutoff);
  Tally t;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const std::vector<int> count = filter(cloud, i);
    std::size_t in_i = 0, counted_i = 0;
    for (std::size_t j = 0; j < cloud.size(); ++j) {
      float d[3];
      for (int a = 0; a < 3; ++a) d[a] = cloud.xyz[3 * j + a] - cloud.xyz[3 * i + a];
      const bool in = j != i && raycut::in_range(raycut::squared_distance(d[0], d[1], d[2]), c2);
      in_i += in;
      counted_i += count[j];
      t.missed += in && count[j] == 0;
      t.repeated += count[j] >= 2;
      t.spurious += !in && count[j] > 0;
      t.self += j == i && count[j] > 0;
    }
    t.in_range += in_i;
    t.counted += counted_i;
    t.targets_over += counted_i > in_i;
    t.targets_under += counted_i < in_i;
  }
  return t;
}

// Our method on the cloud, emulated exactly as tests/test_ray_geometry.cpp does.
Tally ours(Method method, const PointCloud& cloud) {
  const float e = geo::margin(cloud.cutoff, raycut::emulation::largest_magnitude(cloud));
  return tally(cloud, [&](const PointCloud& c, std::size_t i) {
    return raycut::emulation::kept(method, c, i, e);
  });
}

Filter spheres(SphereReport report) {
  return [report](const PointCloud& c, std::size_t i) { return paper_spheres(c, i, report); };
}
Filter squares(Diagonal diagonal) {
  return [diagonal](const PointCloud& c, std::size_t i) { return paper_squares(c, i, diagonal); };
}
Filter boxes(PaperAabb variant) {
  return [variant](const PointCloud& c, std::size_t i) { return paper_aabb(c, i, variant); };
}

// Prints one line for docs/methods.md and records it on the test.
void report(const std::string& what, const PointCloud& cloud, const Tally& t) {
  const std::string line =
      what + " | " + cloud.name + " | in range " + std::to_string(t.in_range) + " | counted " +
      std::to_string(t.counted) + " | missed " + std::to_string(t.missed) + ", repeated " +
      std::to_string(t.repeated) + ", spurious " + std::to_string(t.spurious) + " | targets over " +
      std::to_string(t.targets_over) + ", under " + std::to_string(t.targets_under) +
      (t.self ? " | self " + std::to_string(t.self) : std::string());
  std::cout << "[paper-filters] " << line << "\n";
  std::string key = what + " " + cloud.name;
  for (char& ch : key)
    if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
  ::testing::Test::RecordProperty(key, line);
}

Tally run(const std::string& what, const PointCloud& cloud, const Filter& filter) {
  const Tally t = tally(cloud, filter);
  report(what, cloud, t);
  return t;
}

Tally run_ours(Method method, const PointCloud& cloud) {
  const Tally t = ours(method, cloud);
  report("ours " + raycut::emulation::method_name(method), cloud, t);
  return t;
}

// The inputs on which the paper's filters fail (docs/methods.md, methods 2 and 3).
PointCloud lattice_034() {
  return lattice("lattice 8^3 spacing 0.34C, C=1", 8, 0.34f, 1.0f);
}
PointCloud lattice_half() {
  return lattice("lattice 8^3 spacing C/2, C=1", 8, 0.5f, 1.0f);
}
// Particles at cell centres, as SPH initial conditions place them.
PointCloud lattice_sph() {
  return lattice("SPH-like lattice 12^3 spacing 0.6/51 cell-centred, C=0.02", 12, 0.6f / 51, 0.02f,
                 0.5f);
}

// ---- spheres (method 2) ------------------------------------------------------------------------

TEST(PaperSpheres, MissAboutHalfOfTheUniformPairs) {
  const PointCloud cloud = uniform_box4();
  const Tally paper = run("paper spheres", cloud, spheres(SphereReport::entry_only));
  EXPECT_LT(paper.counted, paper.in_range);
  EXPECT_NEAR(static_cast<double>(paper.counted) / paper.in_range, 0.5, 0.01);
  EXPECT_EQ(paper.repeated, 0u);
  EXPECT_EQ(paper.spurious, 0u);
  EXPECT_TRUE(run_ours(Method::spheres, cloud).exact());
}

TEST(PaperSpheres, MissHalfOfTheLatticePairs) {
  for (const PointCloud& cloud : {lattice_034(), lattice_half(), lattice_sph()}) {
    const Tally paper = run("paper spheres", cloud, spheres(SphereReport::entry_only));
    EXPECT_LT(paper.counted, paper.in_range) << cloud.name;
    EXPECT_EQ(paper.missed, paper.in_range - paper.counted) << cloud.name;
    EXPECT_TRUE(run_ours(Method::spheres, cloud).exact()) << cloud.name;
  }
}

TEST(PaperSpheres, NeverFindCoincidentOrNearCoincidentPairs) {
  // Both segment starts lie inside the other particle's sphere: OptiX reports nothing.
  for (const PointCloud& cloud :
       {pair("coincident pair", 0, 0, 0), pair("pair dx=5e-6", 5e-6f, 0, 0),
        pair("pair d=(3e-6,-4e-6,2e-6)", 3e-6f, -4e-6f, 2e-6f)}) {
    const Tally paper = run("paper spheres", cloud, spheres(SphereReport::entry_only));
    EXPECT_EQ(paper.in_range, 2u) << cloud.name;
    EXPECT_EQ(paper.counted, 0u) << cloud.name;
    EXPECT_TRUE(run_ours(Method::spheres, cloud).exact()) << cloud.name;
  }
}

TEST(PaperSpheres, FindAPairFromOneSideOnly) {
  // The target behind the source starts outside its sphere; the other starts inside.
  for (const PointCloud& cloud :
       {pair("pair d=(0.9,0,0)", 0.9f, 0, 0), pair("pair d=(5e-5,0,0)", 5e-5f, 0, 0)}) {
    const Tally paper = run("paper spheres", cloud, spheres(SphereReport::entry_only));
    EXPECT_EQ(paper.in_range, 2u) << cloud.name;
    EXPECT_EQ(paper.counted, 1u) << cloud.name;
    EXPECT_EQ(paper.targets_under, 1u) << cloud.name;
    EXPECT_TRUE(run_ours(Method::spheres, cloud).exact()) << cloud.name;
  }
}

TEST(PaperSpheres, DoubleCountWhenExitsAreReported) {
  // With C = 1 the x segment [-0.816, 0.816] enters the source's sphere at 0.361 and leaves it at
  // 0.759: entry-only reporting (the built-in spheres) counts it once, exits twice.
  const PointCloud cloud = pair("pair d=(0.56,0.56,0.56)", 0.56f, 0.56f, 0.56f);
  const Tally entry = run("paper spheres", cloud, spheres(SphereReport::entry_only));
  EXPECT_TRUE(entry.exact());
  const Tally both =
      run("paper spheres, exits reported", cloud, spheres(SphereReport::entry_and_exit));
  EXPECT_EQ(both.in_range, 2u);
  EXPECT_EQ(both.counted, 4u);
  EXPECT_EQ(both.repeated, 2u);
  EXPECT_TRUE(run_ours(Method::spheres, cloud).exact());
}

TEST(PaperSpheres, CountSelfFarFromTheOrigin) {
  // At coordinates ~1e5 a float step is ~0.008, far above the radius's 1e-5 widening: the segment
  // start x - l can round to outside the target's own sphere, which the ray then enters; the
  // filter has no index test and keeps |d| = 0 on the x ray (a non-finite Lennard-Jones term).
  const PointCloud cloud = raycut::make_family("offset-1e5", 700, 1.0f, 11);
  const Tally paper = run("paper spheres", cloud, spheres(SphereReport::entry_only));
  EXPECT_GT(paper.self, 0u);
  EXPECT_LT(paper.counted - paper.self, paper.in_range);
  EXPECT_TRUE(run_ours(Method::spheres, cloud).exact());
}

// ---- double squares (method 3) -----------------------------------------------------------------

TEST(PaperTriangles, OverCountUniformPairs) {
  const PointCloud cloud = uniform_box4();
  for (Diagonal diagonal : {Diagonal::both, Diagonal::one}) {
    const Tally paper =
        run(diagonal == Diagonal::both ? "paper triangles" : "paper triangles, one per diagonal",
            cloud, squares(diagonal));
    EXPECT_GT(paper.counted, paper.in_range);
    EXPECT_GT(paper.repeated, 0u);
    EXPECT_EQ(paper.missed, 0u);
  }
  EXPECT_TRUE(run_ours(Method::triangles, cloud).exact());
}

TEST(PaperTriangles, OverCountLatticePairs) {
  for (const PointCloud& cloud : {lattice_034(), lattice_sph(), lattice_half()}) {
    const Tally both = run("paper triangles", cloud, squares(Diagonal::both));
    EXPECT_GT(both.counted, both.in_range) << cloud.name;
    const Tally one = run("paper triangles, one per diagonal", cloud, squares(Diagonal::one));
    if (cloud.name == lattice_half().name) {
      // Exact in binary (C = 1, spacing 1/2): the published ray choice handles dy = 0 and dz = 0,
      // and the device's single report on the shared diagonal makes it exact, as measured.
      EXPECT_TRUE(one.exact()) << cloud.name;
    } else {
      EXPECT_GT(one.counted, one.in_range) << cloud.name;
    }
    EXPECT_TRUE(run_ours(Method::triangles, cloud).exact()) << cloud.name;
  }
}

TEST(PaperTriangles, LatticeOverCountFollowsTheLastBitsOfTheCoordinates) {
  // The same lattices placed differently: with one report per diagonal, the over count comes from
  // the source recovered in float ((max + min) / 2 of the widened square) differing from the
  // particle by an ulp, which defeats the filter's exact-equality cases for dy = 0 or dz = 0.
  const PointCloud clouds[] = {
      lattice("lattice 8^3 spacing 0.34C shifted by half a spacing, C=1", 8, 0.34f, 1.0f, 0.5f),
      lattice("SPH-like lattice 12^3 spacing 0.6/51 from 0, C=0.02", 12, 0.6f / 51, 0.02f)};
  for (const PointCloud& cloud : clouds) {
    EXPECT_GT(run("paper triangles", cloud, squares(Diagonal::both)).counted,
              tally(cloud, boxes(PaperAabb::self_by_index)).in_range);
    run("paper triangles, one per diagonal", cloud, squares(Diagonal::one));
    EXPECT_TRUE(run_ours(Method::triangles, cloud).exact()) << cloud.name;
  }
}

TEST(PaperTriangles, FailOnNearAlignedAndNearCoincidentPairs) {
  struct Case {
    PointCloud cloud;
    std::size_t counted;
  };
  // Generic other components, as in the device probe: 0 < dy <= eps puts two rays in the square's
  // extent; 0 < dx <= eps puts both squares of one source on one ray; the absolute 1e-4 self-hit
  // threshold drops coincident and near-coincident pairs.
  const Case cases[] = {{pair("pair d=(0.3,5e-6,0.4)", 0.3f, 5e-6f, 0.4f), 4},
                        {pair("pair d=(5e-6,0.3,0.4)", 5e-6f, 0.3f, 0.4f), 3},
                        {pair("coincident pair", 0, 0, 0), 0},
                        {pair("pair d=(3e-5,4e-5,0)", 3e-5f, 4e-5f, 0), 0}};
  for (const Case& c : cases) {
    for (Diagonal diagonal : {Diagonal::both, Diagonal::one}) {
      const Tally paper =
          run(diagonal == Diagonal::both ? "paper triangles" : "paper triangles, one per diagonal",
              c.cloud, squares(diagonal));
      EXPECT_EQ(paper.in_range, 2u) << c.cloud.name;
      EXPECT_EQ(paper.counted, c.counted) << c.cloud.name;
    }
    EXPECT_TRUE(run_ours(Method::triangles, c.cloud).exact()) << c.cloud.name;
  }
}

TEST(PaperTriangles, DoubleCountOnTheSharedDiagonal) {
  // dy = dz: the rays of corners (+,+) and (-,-) cross the square on its diagonal; a closed
  // triangle test reports both triangles and the filter keeps both.
  const PointCloud cloud = pair("pair d=(0.3,0.25,0.25)", 0.3f, 0.25f, 0.25f);
  EXPECT_EQ(run("paper triangles", cloud, squares(Diagonal::both)).counted, 4u);
  EXPECT_TRUE(run("paper triangles, one per diagonal", cloud, squares(Diagonal::one)).exact());
  EXPECT_TRUE(run_ours(Method::triangles, cloud).exact());
}

// ---- custom AABB (method 4) --------------------------------------------------------------------

TEST(PaperAabb, TheGeometryIsExactOnEveryInput) {
  // One box per source, visited once by the target's zero-length ray; with THE predicate and self
  // excluded by index (as the paper describes it) the count is exact everywhere.
  std::vector<PointCloud> clouds = {uniform_box4(),
                                    lattice_034(),
                                    lattice_half(),
                                    lattice_sph(),
                                    pair("pair d=(0.3,5e-6,0.4)", 0.3f, 5e-6f, 0.4f),
                                    pair("pair d=(5e-6,0.3,0.4)", 5e-6f, 0.3f, 0.4f),
                                    pair("coincident pair", 0, 0, 0),
                                    pair("pair d=(3e-5,4e-5,0)", 3e-5f, 4e-5f, 0)};
  for (const std::string& family : raycut::family_names())
    clouds.push_back(raycut::make_family(family, 700, 1.0f, 11));
  for (const PointCloud& cloud : clouds) {
    EXPECT_TRUE(tally(cloud, boxes(PaperAabb::self_by_index)).exact()) << cloud.name;
    EXPECT_TRUE(ours(Method::aabb, cloud).exact()) << cloud.name;
  }
  report("paper aabb, self by index", clouds[0], tally(clouds[0], boxes(PaperAabb::self_by_index)));
}

TEST(PaperAabb, PublishedSelfTestDropsCoincidentPairs) {
  // The published intersection programs exclude self by |d|^2 >= 1e-16, not by index.
  for (const PointCloud& cloud :
       {pair("coincident pair", 0, 0, 0), pair("pair d=(3e-9,4e-9,0)", 3e-9f, 4e-9f, 0)}) {
    for (PaperAabb variant : {PaperAabb::unsorted, PaperAabb::sorted}) {
      const Tally paper = run(variant == PaperAabb::unsorted ? "paper aabb" : "paper aabb sorted",
                              cloud, boxes(variant));
      EXPECT_EQ(paper.in_range, 2u);
      EXPECT_EQ(paper.counted, 0u);
    }
  }
  // Everywhere else the unsorted one is exact.
  for (const PointCloud& cloud : {uniform_box4(), lattice_034(), lattice_half(), lattice_sph()})
    EXPECT_TRUE(run("paper aabb", cloud, boxes(PaperAabb::unsorted)).exact()) << cloud.name;
}

TEST(PaperAabb, SortedVariantCountsPairsAtTheCutoff) {
  // Spacing exactly C: every nearest-neighbour pair lies at |d| = C, out of range; the sorted
  // variant's intersection program tests |d|^2 <= C^2.
  const PointCloud cloud = raycut::make_family("lattice-k1", 512, 1.0f, 11);
  const Tally sorted = run("paper aabb sorted", cloud, boxes(PaperAabb::sorted));
  EXPECT_EQ(sorted.in_range, 0u);
  EXPECT_GT(sorted.counted, 0u);
  EXPECT_TRUE(run("paper aabb", cloud, boxes(PaperAabb::unsorted)).exact());
  EXPECT_TRUE(run_ours(Method::aabb, cloud).exact());
}

// ---- cost: candidate hits per target ----------------------------------------------------------

TEST(PaperFilters, CandidateHitsMatchTheVolumeEstimates) {
  // Uniform density n: a ray of length l reports the entry of every sphere whose centre lies in a
  // volume pi r^2 l; a +x segment of length l crosses every face of area A in a volume A l; a
  // zero-length ray lies in every box of volume (2h)^3. Per target, in units of C^3 / n:
  //   spheres    paper 3 pi (2/3) 2 sqrt(2/3) = 10.26    ours 3 pi (2/3) (2 + sqrt(2/3)) = 17.70
  //   triangles  paper 4 rays x 2 squares x C^2 = 8      ours 4 x 2 faces x 2 C^2 = 16
  //   boxes      8 (paper and ours, up to the margin)    (in range: 4 pi / 3 = 4.19)
  // Counted here on the emulated rays, targets far from the walls of a uniform cloud.
  const float c = 1.0f, side = 10.0f;
  raycut::detail::SplitMix64 rng(7);
  std::vector<float> xyz(3 * static_cast<std::size_t>(3000.0 / 64 * side * side * side));
  for (float& x : xyz) x = side * rng.uniform_float();
  const PointCloud cloud = cloud_of("uniform, density 3000/64, 10^3", std::move(xyz), c);
  const double density = cloud.size() / (side * side * side);
  const float e = geo::margin(c, raycut::emulation::largest_magnitude(cloud));
  const geo::SphereRays ours_rays = geo::sphere_rays(c, e);
  const float l = c * 0.81649658092f, r = c * 0.81649658092f + paper_eps;
  double hits[5] = {0, 0, 0, 0, 0};  // paper spheres, ours, paper triangles, ours, boxes
  std::size_t targets = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const float* x = &cloud.xyz[3 * i];
    if (std::fabs(x[0] - 5) > 0.5f || std::fabs(x[1] - 5) > 0.5f || std::fabs(x[2] - 5) > 0.5f)
      continue;
    ++targets;
    for (std::size_t j = 0; j < cloud.size(); ++j) {
      const float* q = &cloud.xyz[3 * j];
      for (int k = 0; k < 3; ++k) {
        Ray paper{{x[0], x[1], x[2]}, {0, 0, 0}, 2 * l}, ours{paper};
        paper.dir[k] = ours.dir[k] = 1;
        paper.o[k] = x[k] - l;
        ours.o[k] = x[k] - ours_rays.back;
        ours.length = ours_rays.length;
        hits[0] += raycut::emulation::sphere_entry(paper, q, r);
        hits[1] += raycut::emulation::sphere_entry(ours, q, ours_rays.radius);
      }
      float v[4][9];
      paper_triangles(q, c, v);
      for (int corner = 0; corner < 4; ++corner) {
        const double py = x[1] + ((corner & 1) ? -c / 2 : c / 2);
        const double pz = x[2] + ((corner & 2) ? -c / 2 : c / 2);
        for (int t = 0; t < 4; ++t) {
          const double hit_t = static_cast<double>(v[t][0]) - (x[0] - c / 2);
          hits[2] +=
              hit_t >= FLT_EPSILON && hit_t <= c * 1.00001 && in_closed_triangle_yz(py, pz, v[t]);
        }
        float o[3], w[9];
        geo::corner_ray_origin(x[0], x[1], x[2], corner, c, e, o);
        const Ray ray{{o[0], o[1], o[2]}, {1, 0, 0}, geo::corner_ray_length(c, e)};
        for (int face = 0; face < 2; ++face) {
          geo::face_triangle(q[0], q[1], q[2], face, c, e, w);
          hits[3] += raycut::emulation::crosses_triangle(ray, w);
        }
      }
      const float h = geo::aabb_half_width(c, e);
      bool inside = true;
      for (int a = 0; a < 3; ++a) inside &= q[a] - h <= x[a] && x[a] <= q[a] + h;
      hits[4] += inside;
    }
  }
  const double pi = 3.14159265358979, k = std::sqrt(2.0 / 3);
  const double expected[5] = {3 * pi * (2.0 / 3) * 2 * k, 3 * pi * (2.0 / 3) * (2 + k), 8, 16, 8};
  const char* names[5] = {"paper spheres", "ours spheres", "paper triangles", "ours triangles",
                          "boxes"};
  ASSERT_GT(targets, 30u);
  for (int m = 0; m < 5; ++m) {
    const double per_target = hits[m] / targets / density;
    std::cout << "[paper-filters] candidate hits per target, " << names[m] << ": " << per_target
              << " C^3/n (estimate " << expected[m] << ")\n";
    EXPECT_NEAR(per_target / expected[m], 1.0, 0.05) << names[m];
  }
}

// ---- all test families, for the record ---------------------------------------------------------

TEST(PaperFilters, EveryFamilyForTheRecord) {
  // No assertion on the paper's filters here (some families happen to pass): the counts go to
  // docs/methods.md. Ours must be exact on all of them (test_ray_geometry.cpp proves it pair by
  // pair; this checks the tallies agree).
  for (const std::string& family : raycut::family_names()) {
    const PointCloud cloud = raycut::make_family(family, 700, 1.0f, 11);
    run("paper spheres", cloud, spheres(SphereReport::entry_only));
    run("paper triangles", cloud, squares(Diagonal::both));
    run("paper triangles, one per diagonal", cloud, squares(Diagonal::one));
    EXPECT_TRUE(ours(Method::spheres, cloud).exact()) << family;
    EXPECT_TRUE(ours(Method::triangles, cloud).exact()) << family;
  }
}

}  // namespace
