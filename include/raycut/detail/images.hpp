// How every traversal (host and device) turns a candidate point into the pair a functor sees:
// the caller's source index j and the image shift S (docs/periodic.md, "Semantics"). The one place
// where periodic images, batches and query points meet the functors. A traversal is instantiated
// with NoImages (the points are the caller's particles: j = k, S = 0, nothing to look up) or
// WithImages (tables of src/core/images.hpp), so plain runs pay nothing for images. with_images
// picks the policy per functor: one that reads neither j nor S (the pair call without j) and
// filters nothing runs as on an open cloud when every point is some particle's image.
#pragma once

#include <cstddef>
#include <cstdint>

#include "raycut/detail/pair_pass.hpp"
#include "raycut/kernels.hpp"

namespace raycut::detail {

struct NoImages {
  static constexpr bool active = false;
  struct Target {};
  RAYCUT_HD Target target(std::uint32_t) const { return {}; }
};

struct WithImages {
  static constexpr bool active = true;
  const PointImage* image;  // ImageTables::table(): by point, or by slot for the grid
  struct Target {
    std::int32_t shift[3];
  };
  RAYCUT_HD Target target(std::uint32_t index) const {
    const PointImage& t = image[index];
    return {{t.shift[0], t.shift[1], t.shift[2]}};
  }
};

// Candidate point k (at `index` in the image table: k, or its slot for the grid) of target i
// (`ti` from images.target()), `in` by the shared predicate: whether functor f takes it, with j
// (the caller's source; a valid index 0 when not taken, for calls fed r2 = +inf) and s set. A
// query point is never a source.
template <class F, class Images>
RAYCUT_HD bool resolve(const F& f, const Images& images, const typename Images::Target& ti, bool in,
                       std::uint32_t i, std::uint32_t k, std::uint32_t index, std::uint32_t& j,
                       Shift& s) {
  if constexpr (Images::active) {
    (void)k;
    j = 0;
    if (!in) return false;
    const PointImage p = images.image[index];
    if (p.source == not_a_source) return false;
    j = p.source;
    s = {p.shift[0] - ti.shift[0], p.shift[1] - ti.shift[1], p.shift[2] - ti.shift[2]};
  } else {
    (void)ti;
    (void)index;
    j = k;
  }
  return in && accepts(f, i, j, s);
}

// a * b and a + b each rounded once, on the device too: nvcc contracts a * b + c into an FMA by
// default, which rounds differently from the host (built with -ffp-contract=off) and could flip
// a pair at the cutoff between a host and a device pass.
RAYCUT_HD double rounded_product(double a, double b) {
#if defined(__CUDA_ARCH__)
  return __dmul_rn(a, b);
#else
  return a * b;
#endif
}
RAYCUT_HD double rounded_sum(double a, double b) {
#if defined(__CUDA_ARCH__)
  return __dadd_rn(a, b);
#else
  return a + b;
#endif
}

// The caller's pair vector r = (x_j - x_i) + S . cell in double (ExactImages), for target point
// i (a particle or a query point), source particle j and shift s; returns |r|^2 in double, with
// the same roundings on host and device. Exactly antisymmetric in (i, j, S) and (j, i, -S): IEEE
// rounding is symmetric.
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
    const double image =
        rounded_sum(rounded_sum(rounded_product(s[0], cell[c]), rounded_product(s[1], cell[3 + c])),
                    rounded_product(s[2], cell[6 + c]));
    r[c] = rounded_sum(xj - xi, image);
  }
  return rounded_sum(rounded_sum(rounded_product(r[0], r[0]), rounded_product(r[1], r[1])),
                     rounded_product(r[2], r[2]));
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
// policy. A functor that needs no tables runs the open traversal (j = the point's index, which
// it does not read) unless a candidate may be a query point, never a source: no per-pair lookup
// or branch, the very loop of an open cloud (measured: 10 % of a periodic LJ pair on the CPU),
// and no deferred table is made. `stream`: where a GPU traversal is launched (null on the host).
template <class F, class Launch>
void with_images(const PairPass& pass, Launch&& launch, void* stream = nullptr) {
  static_assert(check_functor<F>());
  if (pass.images.active() && (needs_images<F> || !pass.images.candidates_are_sources))
    launch(WithImages{pass.images.table(stream)});
  else
    launch(NoImages{});
}

}  // namespace raycut::detail
