// How every traversal (host and device) turns a candidate point into the pair a functor sees:
// the caller's source index j and the image shift S (docs/periodic.md, "Semantics"), and how it
// decides a pair of points with images (in float, or in double in the float band: ExactImages).
// The one place where periodic images, batches and query points meet the functors. A traversal
// is instantiated with one of three policies: NoImages (the points are the caller's particles:
// j = k, S = 0, nothing to look up, the float predicate), WithImages (tables of
// src/core/images.hpp, and the band), or UnreadImages (points with images for a functor that
// reads neither j nor S and filters nothing: the open traversal, j = k, plus the band). So
// plain runs pay nothing for images, and a functor that needs no tables pays one compare per
// pair for the band. with_images picks the policy per functor.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <type_traits>
#include <utility>

#include "raycut/detail/pair_pass.hpp"
#include "raycut/error.hpp"
#include "raycut/kernels.hpp"
#include "raycut/predicate.hpp"

namespace raycut::detail {

struct NoImages {
  static constexpr bool active = false;
  static constexpr bool banded = false;
  struct Target {};
  RAYCUT_HD Target target(std::uint32_t) const { return {}; }
};

struct WithImages {
  static constexpr bool active = true;
  static constexpr bool banded = true;
  const PointImage* image;  // ImageTables::table(): by point, or by slot for the grid
  ExactImages exact;        // by value: plain data, passed to kernels
  struct Target {
    std::int32_t shift[3];
  };
  RAYCUT_HD Target target(std::uint32_t index) const {
    const PointImage& t = image[index];
    return {{t.shift[0], t.shift[1], t.shift[2]}};
  }
};

// Points with images, for a functor that reads neither j nor S: j = k (which it does not read),
// no table read per pair; only the band's decision.
struct UnreadImages {
  static constexpr bool active = false;
  static constexpr bool banded = true;
  ExactImages exact;
  struct Target {};
  RAYCUT_HD Target target(std::uint32_t) const { return {}; }
};

// Candidate point k (at `index` in the image table: k, or its slot for the grid; or `entry`, its
// entry where the pass holds it) of target i (`ti` from images.target()), `in` by the shared
// predicate: whether functor f takes it, with j (the caller's source; a valid index 0 when not
// taken, for calls fed r2 = +inf) and s set. A query point is never a source.
template <class F, class Images>
RAYCUT_HD bool resolve(const F& f, const Images& images, const typename Images::Target& ti, bool in,
                       std::uint32_t i, std::uint32_t k, std::uint32_t index, std::uint32_t& j,
                       Shift& s, const PointImage* entry = nullptr) {
  if constexpr (Images::active) {
    (void)k;
    j = 0;
    if (!in) return false;
    const PointImage p = entry ? *entry : images.image[index];
    if (p.source == not_a_source) return false;
    j = p.source;
    s = {p.shift[0] - ti.shift[0], p.shift[1] - ti.shift[1], p.shift[2] - ti.shift[2]};
  } else {
    (void)ti;
    (void)index;
    (void)entry;
    j = k;
  }
  return in && accepts(f, i, j, s);
}

// A half list whose rows may follow the traversal (ListOptions::any_row; the list functors'
// `any_row`): a traversal that orders its points (the grid's and the cell list's slots, in cell
// order) takes a pair of two home points from its lower slot, which is half its stencil, and
// leaves the pairs with an image point to the list's own rule (grid_pass.cuh, StencilRows).
template <class F, class = void>
struct has_any_row : std::false_type {};
template <class F>
struct has_any_row<F, std::void_t<decltype(std::declval<F&>().any_row)>> : std::true_type {};

// Whether functor f asks for the half stencil.
template <class F>
RAYCUT_HD bool wants_stencil(const F& f) {
  if constexpr (has_any_row<F>::value)
    return f.half && f.any_row;
  else
    return false;
}

// f for a candidate: a home pair, already decided by its slots, is not halved again by index.
template <class F>
RAYCUT_HD decltype(auto) for_candidate(const F& f, bool home) {
  if constexpr (has_any_row<F>::value) {
    F g = f;
    g.half = f.half && !home;
    return g;
  } else {
    (void)home;
    return f;  // by reference: other functors are not copied
  }
}

// Double products and sums rounded one by one, on the device as on the host (built with
// -ffp-contract=off; nvcc would fuse a * b + c): the CPU and CUDA passes then decide every band
// pair, and round its r, bit for bit alike.
RAYCUT_HD double mul_rn(double a, double b) {
#if defined(__CUDA_ARCH__)
  return __dmul_rn(a, b);
#else
  return a * b;
#endif
}
RAYCUT_HD double add_rn(double a, double b) {
#if defined(__CUDA_ARCH__)
  return __dadd_rn(a, b);
#else
  return a + b;
#endif
}

// The caller's pair vector r = (x_j - x_i) + S . cell in double (ExactImages), for target point
// i (a particle or a query point), source particle j and shift s; returns |r|^2 in double.
// Exactly antisymmetric in (i, j, S) and (j, i, -S): IEEE rounding is symmetric.
RAYCUT_HD double exact_pair_vector(const ExactImages& e, std::size_t i, std::uint32_t j,
                                   const double s[3], double r[3]) {
  const PointImage& pi = e.image[i];
  const float* qi = pi.source == not_a_source ? e.queries + 3 * i : nullptr;
  const double* cell = e.cells + 9 * std::size_t{e.system ? e.system[i] : 0};
  for (int c = 0; c < 3; ++c) {
    const double xi = qi            ? qi[c]
                      : e.sources64 ? e.sources64[3 * std::size_t{pi.source} + c]
                                    : e.sources[3 * std::size_t{pi.source} + c];
    const double xj =
        e.sources64 ? e.sources64[3 * std::size_t{j} + c] : e.sources[3 * std::size_t{j} + c];
    const double shift =
        add_rn(add_rn(mul_rn(s[0], cell[c]), mul_rn(s[1], cell[3 + c])), mul_rn(s[2], cell[6 + c]));
    r[c] = add_rn(xj - xi, shift);
  }
  return add_rn(add_rn(mul_rn(r[0], r[0]), mul_rn(r[1], r[1])), mul_rn(r[2], r[2]));
}

// Candidate point k of target point i with images, decided in double from the caller's
// positions (ExactImages): in range iff |r|^2 < C^2 for r = (x_j - x_i) + S . cell, and then r
// and r2 are that vector rounded to float. A query point is never a source.
RAYCUT_HD bool in_range_exact(const ExactImages& e, std::size_t i, std::size_t k, Vec3& r,
                              float& r2) {
  const PointImage& pk = e.image[k];
  if (pk.source == not_a_source) return false;
  const PointImage& pi = e.image[i];
  double s[3], d[3];
  for (int a = 0; a < 3; ++a)
    s[a] = static_cast<double>(std::int64_t{pk.shift[a]} - std::int64_t{pi.shift[a]});
  if (!(exact_pair_vector(e, i, pk.source, s, d) < e.cutoff_squared)) return false;
  r = {static_cast<float>(d[0]), static_cast<float>(d[1]), static_cast<float>(d[2])};
  r2 = squared_distance(r.x, r.y, r.z);
  return true;
}

// The predicate on points with images: a float r2 below the band is in, at or above it out,
// and in it (every r2 below float_out with exact_vectors, where float_in is 0) the pair is
// decided by in_range_exact, which then sets r and r2 from the double vector. Target point i,
// candidate point k (indices of points, not slots).
RAYCUT_HD bool in_range_banded(const ExactImages& e, std::size_t i, std::size_t k, Vec3& r,
                               float& r2) {
  return r2 < e.float_in || (r2 < e.float_out && in_range_exact(e, i, k, r, r2));
}

// The predicate of a traversal under policy `images`: the float one (the very code of an open
// cloud) without images, in_range_banded with them. May replace r and r2 (band pairs).
template <class Images>
RAYCUT_HD bool in_range_of(const Images& images, float cutoff_squared, std::uint32_t i,
                           std::uint32_t k, Vec3& r, float& r2) {
  if constexpr (Images::banded) {
    (void)cutoff_squared;
    return in_range_banded(images.exact, i, k, r, r2);
  } else {
    (void)i;
    (void)k;
    (void)r;
    return in_range(r2, cutoff_squared);
  }
}

// Every float r2 at or above this is out of range under policy `images` (in_range_of says so
// without a look at anything else): the cutoff, or the band's upper edge.
template <class Images>
RAYCUT_HD float out_of_range_from(const Images& images, float cutoff_squared) {
  if constexpr (Images::banded) {
    (void)cutoff_squared;
    return images.exact.float_out;
  } else {
    (void)images;
    return cutoff_squared;
  }
}

// The largest error of a float r2 near cutoff^2 when each coordinate of both points is off by
// up to `rounding` (r_f = p_k - p_i: 2 roundings per component plus its own relative rounding;
// r2 in three roundings; the float cutoff^2 in one), with a factor 2 to spare.
RAYCUT_HD double float_band_slack(double cutoff, double rounding) {
  constexpr double u = 0x1p-24;
  return 2 * (7 * cutoff * rounding + 6 * u * cutoff * cutoff + 12 * rounding * rounding);
}

// Whether functor F needs the image tables: it reads j or S, or filters pairs.
template <class F>
inline constexpr bool needs_images = uses_source<F>::value || has_accepts<F>::value;

// Runs launch(images) with the image policy of `pass` for functor F: one instantiation per
// policy. With images, a functor that needs no tables runs the open traversal (UnreadImages:
// j = the point's index, which it does not read) unless a candidate may be a query point, never
// a source: no per-pair lookup, the loop of an open cloud plus the band's compare (measured: a
// table lookup costs 10 % of a periodic LJ pair on the CPU), and no deferred table is made.
// `stream`: where a GPU traversal is launched (null on the host).
template <class F, class Launch>
void with_images(const PairPass& pass, Launch&& launch, void* stream = nullptr) {
  static_assert(check_functor<F>());
  const ImageTables& images = pass.images;
  if (!images.active()) {
    launch(NoImages{});
    return;
  }
  if (!images.exact)
    throw Error(ErrorCode::internal, std::string("method '") + pass.method +
                                         "': points with images without their exact decision");
  if (needs_images<F> || !images.candidates_are_sources)
    launch(WithImages{images.table(stream), *images.exact});
  else
    launch(UnreadImages{*images.exact});
}

}  // namespace raycut::detail
