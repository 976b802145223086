// A periodic box (docs/periodic.md, "Semantics"): the cell's rows are the lattice vectors a, b, c
// (ASE's convention, any handedness), and pbc says which of them repeat. Host-only helpers:
// validation, face widths, how many images a cutoff needs, and wrapping positions into the cell.
//
// Non-periodic rows take no part in any of it (particles lie anywhere along them, and the contract
// lets those rows be zero or even parallel to a periodic one). Where a computation needs a full
// basis, the periodic rows are completed by unit vectors orthogonal to them (the "effective
// cell"): this gives each periodic axis the largest face width any completion could, and is the
// cell itself when all three axes are periodic.
#pragma once

#include <array>
#include <cstdint>

namespace raycut {

struct Box {
  double cell[3][3] = {};  // rows: lattice vectors a, b, c
  bool pbc[3] = {};        // per lattice vector: does it repeat?

  // No periodic axis and a zero cell: an open system (the default).
  static Box open() { return Box{}; }
  // Rows (lx,0,0), (0,ly,0), (0,0,lz), periodic on the axes given (all by default).
  static Box orthorhombic(double lx, double ly, double lz, bool px = true, bool py = true,
                          bool pz = true) {
    Box box;
    box.cell[0][0] = lx;
    box.cell[1][1] = ly;
    box.cell[2][2] = lz;
    box.pbc[0] = px;
    box.pbc[1] = py;
    box.pbc[2] = pz;
    return box;
  }
  // Some axis is periodic.
  bool periodic() const { return pbc[0] || pbc[1] || pbc[2]; }
  // No axis is periodic and the cell is zero (what open() gives). A box with no periodic axis
  // and a non-zero cell has no images either, but keeps its cell (a file's Lattice, say).
  bool is_open() const {
    if (periodic()) return false;
    for (const auto& row : cell)
      for (double v : row)
        if (v != 0) return false;
    return true;
  }
  // Spelled out: CUDA translation units include this header and compile as C++17.
  bool operator==(const Box& o) const {
    for (int a = 0; a < 3; ++a) {
      if (pbc[a] != o.pbc[a]) return false;
      for (int b = 0; b < 3; ++b)
        if (cell[a][b] != o.cell[a][b]) return false;
    }
    return true;
  }
  bool operator!=(const Box& o) const { return !(*this == o); }
};

// Throws Error(invalid_argument), with a message naming the problem, when:
//   - an entry of the cell is not finite (any row, periodic or not);
//   - a periodic row has zero length;
//   - the periodic rows are (nearly) linearly dependent: |det| of the effective cell with each
//     row scaled to unit length is below 1e-6. That is the volume of the cell relative to the
//     product of its row lengths (1 for orthogonal rows); for two periodic rows it is the sine
//     of their angle, so two rows closer than 1e-6 rad to parallel are refused. Scaling first
//     makes the test independent of units and free of overflow and underflow.
// Non-periodic rows may be anything finite (zero, or parallel to a periodic row).
void validate(const Box& box);

// The distance between the two faces of the effective cell normal to `axis` (0, 1, 2): its
// volume over |cross product of the other two rows|, e.g. |a| sin(angle) for a periodic row a
// with one other periodic row at that angle. +infinity on a non-periodic axis (no faces).
// Validates the box first (the errors of validate()); Error(invalid_argument) for an axis
// outside 0..2.
double face_width(const Box& box, int axis);

// Minimum image suffices: every periodic face width is >= 2 cutoff (true for a box with no
// periodic axis). Error(invalid_argument) for a cutoff that is not finite and > 0, and the
// errors of validate().
bool minimum_image_ok(const Box& box, double cutoff);

// Images per periodic axis, m_k = ceil(cutoff / face_width_k) (0 on a non-periodic axis): for
// positions wrapped into the (effective) cell, every pair (i, j, S) with |r_ij| < cutoff has
// |S_k| <= m_k. (Both fractional coordinates lie in [0, 1), so their difference in (-1, 1);
// the fractional coordinate of r_ij along k is at most cutoff / width_k in magnitude.)
// Error(invalid_argument) for a cutoff that is not finite and > 0, for an m_k above 2^30 (a
// cell far too thin for the cutoff), and the errors of validate().
std::array<int, 3> image_range(const Box& box, double cutoff);

// The reciprocal rows g_k of the effective cell: the fractional coordinate of x along axis k is
// x . g_k (g_k . row_m = delta_km), |g_k| = 1 / face width. The errors of validate().
std::array<std::array<double, 3>, 3> reciprocal_rows(const Box& box);

// A position wrapped into the cell: x = wrapped + shift . cell (shift as a row vector; 0 on
// non-periodic axes, where wrapped equals x).
struct Wrapped {
  std::array<double, 3> x{};
  std::array<std::int32_t, 3> shift{};
};

// Wraps x along the periodic axes, in double, through fractional coordinates f = x . G (G: the
// reciprocal basis of the effective cell): shift_k = floor(f_k), nudged so that f_k - shift_k
// lies in [0, 1) (a tiny negative f_k whose f_k + 1 rounds to 1 keeps shift 0); then wrapped =
// x - shift . cell. The wrapped position's fractional coordinates, recomputed, lie in [0, 1) up
// to double rounding (~1e-16 |x| / width).
//
// For pairs found among wrapped positions w_i = x_i - n_i . cell, with shift S_w, the shift for
// the caller's positions is S = S_w + n_i - n_j (r_ij = x_j - x_i + S . cell is the same vector).
//
// Error(invalid_argument) for a non-finite x, or a shift outside the int32 range (a position
// more than 2^31 boxes away; lists give shifts as int32), and the errors of
// validate().
Wrapped wrap(const Box& box, const std::array<double, 3>& x);

}  // namespace raycut
