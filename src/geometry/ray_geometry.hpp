// The geometry of the ray-tracing methods, as host+device code: primitives, rays and the filter
// that keeps each in-range pair on exactly one (ray, primitive) hit. The OptiX programs call it;
// so does the CPU emulation in tests/test_ray_geometry.cpp, which casts the same rays at the same
// primitives so that CI (no GPU) proves the filters exactly-once on every input family.
//
// Every method widens its primitives by a margin e = C 2^-10 + M 2^-20 (M the largest coordinate
// magnitude, in the local frame below): far above float round-off of positions, vertices and hit
// tests, so a hit the filter needs is always reported. Widening only adds candidates; the filter
// uses positions.
//
// Local frame and valid domain (docs/methods.md, "Valid domain of each ray-tracing method"): the
// host shifts the positions by a per-axis origin c chosen so that x - c is EXACT in float for
// every particle (exact_shift), which leaves every pair vector d = x_j - x_i bit for bit what the
// caller's floats give, and refuses scenes whose extent from c, in cutoffs, exceeds the bound of
// the method's geometry (max_scene_cutoffs).
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>

#include "raycut/predicate.hpp"

namespace raycut::detail::geometry {

RAYCUT_HD float margin(float cutoff, float max_abs_coordinate) {
  return cutoff * 0x1p-10f + max_abs_coordinate * 0x1p-20f;
}

// ---- spheres (method 2) ------------------------------------------------------------------------
// A source is a sphere of radius C sqrt(2/3) + e. A target casts 3 rays, one per axis k, from
// x - L e_k with L = C + r + e, of length 2C + r + 2e. Why L: no in-range sphere contains the
// origin (OptiX built-in spheres report the entry only, and nothing for a ray starting inside),
// and every in-range sphere is entered inside the segment on the axis that keeps the pair, whose
// line passes within sqrt(2/3)|d| < r of the centre.
struct SphereRays {
  float radius, back, length;
};

RAYCUT_HD SphereRays sphere_rays(float cutoff, float e) {
  const float r = cutoff * 0.81649658f + e;  // sqrt(2/3)
  return {r, cutoff + r + e, 2 * cutoff + r + 2 * e};
}

// The one axis that keeps the pair: largest |d_k|, ties to the lowest k.
RAYCUT_HD int sphere_axis(float dx, float dy, float dz) {
  const float ax = fabsf(dx), ay = fabsf(dy), az = fabsf(dz);
  if (ax >= ay && ax >= az) return 0;
  return ay >= az ? 1 : 2;
}

// ---- double squares (method 3), one oversized triangle per square ------------------------------
// A source has two faces perpendicular to x, at q_x - C/2 (face 0) and q_x + C/2 (face 1). Each
// face is ONE triangle covering the square q_yz +- (C/2 + e) with room to spare (legs along two
// sides, hypotenuse beyond the far corner): no shared diagonal, so no double report on it, and
// half the primitives of the paper's two triangles per square. A target casts 4 rays along +x
// from its box's corners (y +- C/2, z +- C/2), starting at x - C/2 - e, of length C + 2e.
// The pair is kept on exactly one (corner, face): corner = signs of (dy, dz) (0 counts as +),
// face 0 when dx >= 0, else face 1; that ray crosses that face at a point at least e inside the
// triangle and at least e inside the segment.
RAYCUT_HD float triangle_half_extent(float cutoff, float e) {
  return cutoff * 0.5f + 2 * e;
}

// Vertices (y, z offsets from the source) of the face triangle: (-h,-h), (3h,-h), (-h,3h).
RAYCUT_HD void face_triangle(float qx, float qy, float qz, int face, float cutoff, float e,
                             float v[9]) {
  const float x = face == 0 ? qx - cutoff * 0.5f : qx + cutoff * 0.5f;
  const float h = triangle_half_extent(cutoff, e);
  const float lo_y = qy - h, lo_z = qz - h, hi_y = qy + 3 * h, hi_z = qz + 3 * h;
  v[0] = x, v[1] = lo_y, v[2] = lo_z;
  v[3] = x, v[4] = hi_y, v[5] = lo_z;
  v[6] = x, v[7] = lo_y, v[8] = hi_z;
}

// Corner c: bit 0 set for -y, bit 1 set for -z.
RAYCUT_HD void corner_ray_origin(float x, float y, float z, int corner, float cutoff, float e,
                                 float origin[3]) {
  const float half = cutoff * 0.5f;
  origin[0] = x - half - e;
  origin[1] = (corner & 1) ? y - half : y + half;
  origin[2] = (corner & 2) ? z - half : z + half;
}

RAYCUT_HD float corner_ray_length(float cutoff, float e) {
  return cutoff + 2 * e;
}

RAYCUT_HD int kept_corner(float dy, float dz) {
  return (dy >= 0 ? 0 : 1) | (dz >= 0 ? 0 : 2);
}
RAYCUT_HD int kept_face(float dx) {
  return dx >= 0 ? 0 : 1;
}

// ---- custom AABB (method 4) --------------------------------------------------------------------
// A source is a box of half-width C + e; a target casts one zero-length ray from its position.
RAYCUT_HD float aabb_half_width(float cutoff, float e) {
  return cutoff + e;
}

// ---- local frame and valid domain (host only) -------------------------------------------------
enum class Shape { spheres, triangles, aabb };

// Does x - c round exactly, for every float x in [lo, hi]? Every float of magnitude >= m is a
// multiple of g = 2^(exponent(m) - 23); when [lo, hi] and c lie on one side of 0, with m the
// smallest magnitude there, x - c is a multiple of g of magnitude <= 2^24 g, so it has at most 24
// significant bits: exact. (Sterbenz's lemma is the case hi <= 2 lo.) c = 0 is always exact.
inline bool shift_is_exact(float lo, float hi, float c) {
  if (c == 0) return true;
  const double a = std::fmin(lo, c), b = std::fmax(hi, c);
  if (!(a > 0 || b < 0)) return false;  // the range and c must not straddle 0
  const double m = std::fmin(std::fabs(a), std::fabs(b));
  // Below FLT_MIN the floats are the multiples of 2^-149.
  const int exponent = std::max(std::ilogb(m), std::numeric_limits<float>::min_exponent - 1);
  const double grid = std::ldexp(1.0, exponent - 23);
  return std::fmax(std::fabs(double{lo} - c), std::fabs(double{hi} - c)) <= std::ldexp(grid, 24);
}

// The local origin of one axis whose floats span [lo, hi]: the centre rounded to a float when the
// shift is exact for the whole range (a compact cloud far from 0), else 0 (the range holds 0 or
// reaches near it: there |x| <= 2 (hi - lo) already, and centring would gain at most a factor 4).
inline float exact_shift(float lo, float hi) {
  const float c = static_cast<float>(0.5 * (double{lo} + double{hi}));
  return shift_is_exact(lo, hi, c) ? c : 0.0f;
}

// The largest coordinate magnitude S in the local frame, |x - c| over the box (exact in double).
inline double local_magnitude(const float lo[3], const float hi[3], const float c[3]) {
  double s = 0;
  for (int a = 0; a < 3; ++a)
    s = std::fmax(s, std::fmax(std::fabs(double{lo[a]} - c[a]), std::fabs(double{hi[a]} - c[a])));
  return s;
}

// The largest S / C each geometry supports: the margin e = C 2^-10 + S 2^-20 may grow the
// primitive's cutoff-sized dimension by at most a quarter. Spheres: e <= r0 / 4, r0 = C sqrt(2/3).
// Triangles: the half-extent h = C/2 + 2e, so 2e <= (C/2) / 4. Boxes: e <= C / 4. Beyond, errors
// proportional to S (float rounding in OptiX's BVH, traversal and intersectors, which OptiX does
// not bound) need a margin that is no longer small against C, and the cost grows as ((C+e)/C)^3
// to O(N) candidates per target (docs/methods.md, "Valid domain of each ray-tracing method").
inline double max_scene_cutoffs(Shape shape) {
  const double growth = shape == Shape::spheres     ? 0.81649658 / 4
                        : shape == Shape::triangles ? 1.0 / 16
                                                    : 1.0 / 4;
  return (growth - 0x1p-10) * 0x1p20;
}

}  // namespace raycut::detail::geometry
