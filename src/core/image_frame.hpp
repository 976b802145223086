// Periodic images of one point, host and device alike (src/core/images.cpp, src/cuda/images.cu):
// the point wrapped into its system's cell, then every image of it that can lie within the
// cutoff of the cell. In double; one point in, its images out, in a fixed order (deterministic
// layouts, whatever runs it).
//
// Why this is complete: a target t wrapped into the cell has fractional coordinates f_t in
// [0, 1) along each periodic axis k, and a pair (t, image p + n . cell) in range has
// |f_p + n_k - f_t| <= |r| / width_k < C / width_k. So every image a target can meet has
// f_p + n_k in (-C / width_k, 1 + C / width_k): those are the images kept (with a margin).
#pragma once

#include <cmath>
#include <cstdint>

#include "raycut/predicate.hpp"

namespace raycut::detail {

// One system's box, as the expansion needs it (plain data: copied to the device as is).
struct ImageFrame {
  double cell[3][3] = {};        // rows: lattice vectors
  double reciprocal[3][3] = {};  // f_k = x . reciprocal[k] on periodic axes k
  double origin[3] = {};         // subtracted from every point of the system (its own frame)
  double reach[3] = {};          // periodic k: images kept with f_k in (-reach, 1 + reach)
  bool pbc[3] = {};
};

// A point's wrapped position (double) and integer shift W: x = wrapped + W . cell. `ok` false
// when some |W_k| would leave the int32 range (a position over 2^31 boxes away).
struct WrappedPoint {
  double x[3];
  double f[3];  // fractional coordinates of the wrapped point on periodic axes
  std::int32_t shift[3];
  bool ok;
};

// `Real`: float, or double for float64 positions (Engine::build(Float64Positions), host).
template <class Real>
RAYCUT_HD WrappedPoint wrap_point(const ImageFrame& frame, const Real* xyz) {
  WrappedPoint w{};
  w.ok = true;
  const double x[3] = {xyz[0], xyz[1], xyz[2]};
  for (int c = 0; c < 3; ++c) w.x[c] = x[c];
  for (int k = 0; k < 3; ++k) {
    if (!frame.pbc[k]) continue;
    const double f = x[0] * frame.reciprocal[k][0] + x[1] * frame.reciprocal[k][1] +
                     x[2] * frame.reciprocal[k][2];
    double s = floor(f);
    if (f - s >= 1) s += 1;  // f tiny and negative: f + 1 rounds to 1
    if (!(s >= -2147483648.0 && s < 2147483648.0)) {
      w.ok = false;
      s = 0;
    }
    w.shift[k] = static_cast<std::int32_t>(s);
    w.f[k] = f - s;
  }
  for (int k = 0; k < 3; ++k)
    for (int c = 0; c < 3; ++c) w.x[c] -= w.shift[k] * frame.cell[k][c];
  return w;
}

// The image offsets n kept along axis k for a wrapped point: [lo, hi] (0 on open axes).
RAYCUT_HD void image_span(const ImageFrame& frame, const WrappedPoint& w, int k, int& lo, int& hi) {
  lo = hi = 0;
  if (!frame.pbc[k]) return;
  // n with f + n > -reach and f + n < 1 + reach.
  lo = static_cast<int>(floor(-frame.reach[k] - w.f[k])) + 1;
  hi = static_cast<int>(ceil(1 + frame.reach[k] - w.f[k])) - 1;
}

// Calls emit(n, position) for the images of the wrapped point w, n = (n0, n1, n2) in
// lexicographic order, n = 0 included only when `with_self`. Returns how many.
template <class Emit>
RAYCUT_HD std::uint64_t for_each_image(const ImageFrame& frame, const WrappedPoint& w,
                                       bool with_self, Emit&& emit) {
  int lo[3], hi[3];
  for (int k = 0; k < 3; ++k) image_span(frame, w, k, lo[k], hi[k]);
  std::uint64_t count = 0;
  for (int a = lo[0]; a <= hi[0]; ++a)
    for (int b = lo[1]; b <= hi[1]; ++b)
      for (int c = lo[2]; c <= hi[2]; ++c) {
        if (!with_self && a == 0 && b == 0 && c == 0) continue;
        const int n[3] = {a, b, c};
        float p[3];
        for (int d = 0; d < 3; ++d)
          p[d] = static_cast<float>(w.x[d] + a * frame.cell[0][d] + b * frame.cell[1][d] +
                                    c * frame.cell[2][d] - frame.origin[d]);
        emit(n, p);
        ++count;
      }
  return count;
}

// The frame origin of a system of a batch, from its first point: that point's components along
// the non-periodic directions (its wrapped position less its periodic part), so that every
// system lies near the origin, each in its own frame, whatever its absolute position.
template <class Real>
RAYCUT_HD void system_origin(ImageFrame& frame, const Real* first) {
  const WrappedPoint w = wrap_point(frame, first);
  for (int c = 0; c < 3; ++c) {
    double o = w.x[c];
    for (int k = 0; k < 3; ++k)
      if (frame.pbc[k]) o -= w.f[k] * frame.cell[k][c];
    frame.origin[c] = o;
  }
}

// The largest |coordinate| of the wrapped point w and of every image for_each_image emits for
// it, without computing them (each coordinate is linear in n, so its extremes lie at corners of
// the box of kept offsets), in double: the float points are within half an ulp of it.
RAYCUT_HD double image_extent(const ImageFrame& frame, const WrappedPoint& w) {
  int lo[3], hi[3];
  for (int k = 0; k < 3; ++k) image_span(frame, w, k, lo[k], hi[k]);
  double extent = 0;
  for (int d = 0; d < 3; ++d) {
    double low = w.x[d] - frame.origin[d], high = low;
    for (int k = 0; k < 3; ++k) {
      const double a = lo[k] * frame.cell[k][d], b = hi[k] * frame.cell[k][d];
      low += a < b ? a : b;
      high += a < b ? b : a;
    }
    const double m = fabs(low) > fabs(high) ? fabs(low) : fabs(high);
    extent = extent > m ? extent : m;
  }
  return extent;
}

// How many images for_each_image emits, without computing them.
RAYCUT_HD std::uint64_t image_count(const ImageFrame& frame, const WrappedPoint& w,
                                    bool with_self) {
  std::uint64_t count = 1;
  for (int k = 0; k < 3; ++k) {
    int lo, hi;
    image_span(frame, w, k, lo, hi);
    count *= static_cast<std::uint64_t>(hi - lo + 1);
  }
  return with_self ? count : count - 1;
}

}  // namespace raycut::detail
