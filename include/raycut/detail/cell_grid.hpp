// Cell coordinates shared by every grid method (CPU cell list, CUDA grids), host and device.
//
// Why the care: a pair that the float predicate calls in range must land in cells at most
// `reach` apart. The cell width is inflated by a relative margin (far above float round-off of
// the predicate) and coordinates are computed in double, where x - origin is exact and the
// scaling error is ~1e-16 of a cell, so no rounding can split a pair by one cell too many.
// Dimensions are capped at 2^21 cells per axis (a far outlier widens the cells instead of
// growing the key space), so a row-major key always fits in 64 bits.
#pragma once

#include <cmath>
#include <cstdint>

#include "raycut/predicate.hpp"

namespace raycut::detail {

struct CellGrid {
  static constexpr std::uint32_t max_dim = 1u << 21;
  static constexpr double width_margin = 1e-4;

  double origin[3] = {0, 0, 0};
  double inverse_width = 1;  // cells per unit length
  double width = 1;
  std::uint32_t dims[3] = {1, 1, 1};
  int reach = 1;  // a pair in range is at most `reach` cells apart on each axis

  RAYCUT_HD std::uint32_t coord(float x, int axis) const {
    const double c = floor((static_cast<double>(x) - origin[axis]) * inverse_width);
    if (!(c > 0)) return 0;  // also catches a NaN that validation should have refused
    const double last = static_cast<double>(dims[axis] - 1);
    return static_cast<std::uint32_t>(c < last ? c : last);
  }

  // Row-major: consecutive x cells are consecutive keys (a stencil row is one key range).
  RAYCUT_HD std::uint64_t key(std::uint32_t ix, std::uint32_t iy, std::uint32_t iz) const {
    return (static_cast<std::uint64_t>(iz) * dims[1] + iy) * dims[0] + ix;
  }

  RAYCUT_HD std::uint64_t key_of(float x, float y, float z) const {
    return key(coord(x, 0), coord(y, 1), coord(z, 2));
  }

  std::uint64_t cell_count() const {
    return static_cast<std::uint64_t>(dims[0]) * dims[1] * dims[2];
  }
};

// A grid over the box [lo, hi] whose cells are cutoff / cells_per_cutoff wide (a little more,
// see above), or wider when the box would need more than 2^21 cells on an axis.
inline CellGrid make_cell_grid(const float lo[3], const float hi[3], float cutoff,
                               int cells_per_cutoff = 1) {
  CellGrid g;
  double extent = 0;
  for (int a = 0; a < 3; ++a) {
    extent = std::fmax(extent, static_cast<double>(hi[a]) - static_cast<double>(lo[a]));
  }
  double width = static_cast<double>(cutoff) / cells_per_cutoff * (1.0 + CellGrid::width_margin);
  const double widest = extent / (CellGrid::max_dim - 2);
  if (width < widest) width = widest;
  g.width = width;
  g.inverse_width = 1.0 / width;
  // Cells wider than cutoff / cells_per_cutoff still hold every pair within `reach` of them.
  g.reach = cells_per_cutoff;
  for (int a = 0; a < 3; ++a) {
    g.origin[a] = lo[a];
    const double span = (static_cast<double>(hi[a]) - g.origin[a]) * g.inverse_width;
    g.dims[a] = static_cast<std::uint32_t>(std::floor(span)) + 1;
    if (g.dims[a] > CellGrid::max_dim) g.dims[a] = CellGrid::max_dim;
  }
  return g;
}

}  // namespace raycut::detail
