// The per-particle arithmetic of the decomposition (Decomposition, raycut/mpi/distributed.hpp)
// in plain data: wrapping into the cell, owners, periodic images, the halo records a particle
// sends. One implementation for the host's exchange (distributed.cpp) and the GPU's
// (device_residence.cu). Both compile it without FMA contraction (the host with
// -ffp-contract=off, the device file with --fmad=false) and IEEE double division, so both make
// the same floats, owners and halo records, bit for bit.
#pragma once

#include <cmath>
#include <cstdint>

#include "raycut/predicate.hpp"  // RAYCUT_HD

namespace raycut::mpi::detail {

struct Domains {
  int dims[3];
  bool periodic[3];
  bool images[3];   // Decomposition::images: halos carry image shifts along the axis
  bool crossed[3];  // Decomposition::halo_axis: halos cross the faces across the axis
  bool aligned, orthogonal;
  double length[3];
  double normal[3][3];
  double cell[3][3];      // rows: images are x + S . cell
  const double* cuts[3];  // dims[a] + 1 each (Decomposition::cuts), host or device memory

  RAYCUT_HD double coordinate(int axis, const float* x) const {
    const double* n = normal[axis];
    return static_cast<double>(x[0]) * n[0] + static_cast<double>(x[1]) * n[1] +
           static_cast<double>(x[2]) * n[2];
  }

  // The inner cuts <= u (so clamped to the grid; NaN: 0): std::upper_bound over them.
  RAYCUT_HD int slab(int axis, double u) const {
    if (dims[axis] == 1 || u != u) return 0;
    int low = 0, high = dims[axis] - 1;
    while (low < high) {
      const int mid = (low + high) / 2;
      if (cuts[axis][1 + mid] <= u)
        low = mid + 1;
      else
        high = mid;
    }
    return low;
  }

  // The owning domain (= rank); an axis of one domain needs no coordinate.
  RAYCUT_HD int owner(const float* x) const {
    int domain = 0;
    for (int a = 0; a < 3; ++a)
      domain = domain * dims[a] + (dims[a] > 1 ? slab(a, coordinate(a, x)) : 0);
    return domain;
  }

  RAYCUT_HD void coords(int domain, int c[3]) const {
    c[0] = domain / (dims[1] * dims[2]);
    c[1] = (domain / dims[2]) % dims[1];
    c[2] = domain % dims[2];
  }

  // A position wrapped into the cell along the periodic axes: coordinate by coordinate into
  // [0, L) when aligned, else through the fractional coordinates f_k = u_k / w_k, as
  // raycut::wrap: x - floor(f) . cell.
  RAYCUT_HD void wrap(float* x) const {
    if (aligned) {
      for (int a = 0; a < 3; ++a)
        if (periodic[a]) x[a] = wrap_coordinate(x[a], length[a]);
      return;
    }
    double w[3] = {x[0], x[1], x[2]};
    for (int k = 0; k < 3; ++k) {
      if (!periodic[k]) continue;
      const double f = coordinate(k, x) / length[k];
      double s = floor(f);
      if (f - s >= 1) s += 1;
      for (int c = 0; c < 3; ++c) w[c] -= s * cell[k][c];
    }
    for (int c = 0; c < 3; ++c) x[c] = static_cast<float>(w[c]);
  }

  // The image x + S . cell: in double, then rounded to float, as the single-rank engine makes
  // its images (core/image_frame.hpp).
  RAYCUT_HD void image(const float* x, const std::int32_t* s, float* out) const {
    const bool zero = s[0] == 0 && s[1] == 0 && s[2] == 0;
    for (int c = 0; c < 3; ++c)
      out[c] = zero ? x[c]
                    : static_cast<float>(static_cast<double>(x[c]) + s[0] * cell[0][c] +
                                         s[1] * cell[1][c] + s[2] * cell[2][c]);
  }

  // Wraps a coordinate into [0, L) in double (the float result may round up to L itself).
  RAYCUT_HD static float wrap_coordinate(float v, double length) {
    const double x = v;
    double w = x - floor(x / length) * length;
    if (w >= length) w -= length;
    if (w < 0) w += length;
    return static_cast<float>(w);
  }
};

// The faces of a domain that halos cross (not a local axis's, nor the outer face of an open end
// slab), else -inf / +inf: a particle of the domain farther than the halo reach from all of them
// sends no halo and meets none.
struct Faces {
  double low[3], high[3];
  RAYCUT_HD Faces(const Domains& d, int domain) {
    int c[3];
    d.coords(domain, c);
    for (int a = 0; a < 3; ++a) {
      const bool crossed = d.crossed[a];
      low[a] = crossed && (d.images[a] || c[a] > 0) ? d.cuts[a][c[a]] : -HUGE_VAL;
      high[a] = crossed && (d.images[a] || c[a] < d.dims[a] - 1) ? d.cuts[a][c[a] + 1] : HUGE_VAL;
    }
  }
  RAYCUT_HD bool near(const Domains& d, const float* x, double reach) const {
    for (int a = 0; a < 3; ++a) {
      if (low[a] == -HUGE_VAL && high[a] == HUGE_VAL) continue;  // no coordinate needed
      const double u = d.coordinate(a, x);
      if (u - low[a] < reach || high[a] - u < reach) return true;
    }
    return false;
  }
};

// Every halo record of the owned particle at x of domain `rank`: emit(q, S) (q the destination
// domain, S the image shift, 3 int32) for every image of it, shifted along the axes with images,
// within `reach` of domain q (its own too, for an image shifted by a period), in the order the
// halo plan sends them: by x's candidates, then y's, then z's, each by shift, then slab.
// Local axes get no shift and no test (the local engines image every point they hold along
// them). docs/distributed.md and DistributedEngine::build_halos say why this is complete.
template <class Emit>
RAYCUT_HD void for_each_halo(const Domains& d, const Faces& faces, int rank, double reach,
                             const float* x, Emit&& emit) {
  // Farther than the reach from every crossed face of its domain (it is owned: inside it), a
  // particle has no candidate along any axis but its own slab, unshifted.
  if (!faces.near(d, x, reach)) return;
  int own[3];
  d.coords(rank, own);
  // f(slab, shift, gap^2) for each candidate along axis a.
  const auto candidates = [&](int a, auto&& f) {
    if (!d.crossed[a]) {
      f(own[a], 0, 0.0);
      return;
    }
    const double u = d.coordinate(a, x);
    const bool images = d.images[a];
    const int last_slab = d.dims[a] - 1;
    for (std::int32_t s = images ? -1 : 0; s <= (images ? 1 : 0); ++s) {
      // A shift by cell row a moves u_a by one face width; the other rows leave it.
      const double y = u + s * d.length[a];
      const int first = d.slab(a, y - reach), last = d.slab(a, y + reach);
      for (int k = first; k <= last; ++k) {
        // An open axis's end slabs extend to infinity; a local axis's one slab is all of it.
        const bool open_low = !images && k == 0;
        const bool open_high = !images && k == last_slab;
        const double lo = d.cuts[a][k], hi = d.cuts[a][k + 1];
        double gap = 0;
        if (!open_low && y < lo) gap = lo - y;
        if (!open_high && y > hi) gap = y - hi;
        if (gap < reach) f(k, s, gap * gap);
      }
    }
  };
  const double reach2 = reach * reach;
  candidates(0, [&](int kx, std::int32_t sx, double gx) {
    candidates(1, [&](int ky, std::int32_t sy, double gy) {
      candidates(2, [&](int kz, std::int32_t sz, double gz) {
        if (d.orthogonal && gx + gy + gz >= reach2) return;
        const int q = (kx * d.dims[1] + ky) * d.dims[2] + kz;
        if (q == rank && sx == 0 && sy == 0 && sz == 0) return;
        const std::int32_t shift[3] = {sx, sy, sz};
        emit(q, shift);
      });
    });
  });
}

}  // namespace raycut::mpi::detail
