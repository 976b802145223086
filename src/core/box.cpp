// Periodic boxes (include/raycut/box.hpp): validation, face widths, image counts, wrapping. All
// in double, on rows scaled to unit length first (lengths kept apart), so that no product of
// cell entries can overflow or underflow whatever the units.
#include "raycut/box.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <string>

#include "raycut/error.hpp"

namespace raycut {
namespace {

using Vec = std::array<double, 3>;

constexpr const char* row_names[3] = {"a", "b", "c"};
constexpr double min_normalized_volume = 1e-6;

[[noreturn]] void refuse(const std::string& what) {
  throw Error(ErrorCode::invalid_argument, "periodic box: " + what);
}

Vec cross(const Vec& u, const Vec& v) {
  return {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]};
}
double dot(const Vec& u, const Vec& v) {
  return u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
}

// v = length * unit, computed without overflow or underflow (scaled by the largest component
// first); length 0 and unit 0 for a zero vector.
void split(const Vec& v, double& length, Vec& unit) {
  const double scale = std::max({std::abs(v[0]), std::abs(v[1]), std::abs(v[2])});
  if (scale == 0) {
    length = 0;
    unit = {0, 0, 0};
    return;
  }
  const Vec s = {v[0] / scale, v[1] / scale, v[2] / scale};
  const double norm = std::sqrt(dot(s, s));
  length = scale * norm;
  unit = {s[0] / norm, s[1] / norm, s[2] / norm};
}

Vec normalized(const Vec& v) {
  double length = 0;
  Vec unit{};
  split(v, length, unit);
  return unit;
}

std::string vector_text(const double row[3]) {
  char text[128];
  std::snprintf(text, sizeof text, "(%.17g, %.17g, %.17g)", row[0], row[1], row[2]);
  return text;
}

// The effective cell (box.hpp) as unit rows and lengths (length 1 for completion rows), and the
// determinant of the unit rows. Validates on the way.
struct Basis {
  Vec unit[3]{};
  double length[3] = {1, 1, 1};
  double det = 0;  // of the unit rows: |det| in (1e-6, 1]
};

Basis effective_basis(const Box& box) {
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) {
      if (!std::isfinite(box.cell[r][c])) {
        refuse(std::string("cell row ") + row_names[r] + " = " + vector_text(box.cell[r]) +
               " has a non-finite entry");
      }
    }
  }
  Basis basis;
  int periodic[3], count = 0;
  for (int r = 0; r < 3; ++r) {
    if (!box.pbc[r]) continue;
    periodic[count++] = r;
    split({box.cell[r][0], box.cell[r][1], box.cell[r][2]}, basis.length[r], basis.unit[r]);
    if (basis.length[r] == 0) {
      refuse(std::string("periodic lattice vector ") + row_names[r] +
             " has zero length (a periodic axis needs a non-zero cell row)");
    }
  }
  if (count == 2) {
    const int open = 3 - periodic[0] - periodic[1];
    basis.unit[open] = normalized(cross(basis.unit[periodic[0]], basis.unit[periodic[1]]));
  } else if (count == 1) {
    const Vec& a = basis.unit[periodic[0]];
    // The coordinate axis least aligned with a, crossed with a, then a third at right angles.
    int least = 0;
    for (int k = 1; k < 3; ++k)
      if (std::abs(a[k]) < std::abs(a[least])) least = k;
    Vec e{0, 0, 0};
    e[least] = 1;
    const Vec u = normalized(cross(a, e));
    const Vec v = cross(a, u);
    basis.unit[(periodic[0] + 1) % 3] = u;
    basis.unit[(periodic[0] + 2) % 3] = v;
  } else if (count == 0) {
    basis.unit[0] = {1, 0, 0};
    basis.unit[1] = {0, 1, 0};
    basis.unit[2] = {0, 0, 1};
  }
  basis.det = dot(basis.unit[0], cross(basis.unit[1], basis.unit[2]));
  if (!(std::abs(basis.det) >= min_normalized_volume)) {
    std::string rows;
    for (int k = 0; k < count; ++k) {
      rows += std::string(k == 0 ? "" : ", ") + row_names[periodic[k]] + " = " +
              vector_text(box.cell[periodic[k]]);
    }
    char ratio[64];
    std::snprintf(ratio, sizeof ratio, "%.3g", std::abs(basis.det));
    refuse("the periodic lattice vectors " + rows +
           " are (nearly) linearly dependent: a singular cell (volume / product of the row "
           "lengths = " +
           ratio + ", below " + "1e-6)");
  }
  return basis;
}

void require_axis(int axis) {
  if (axis < 0 || axis > 2) refuse("axis " + std::to_string(axis) + " is not 0, 1 or 2");
}

void require_cutoff(double cutoff) {
  if (!(std::isfinite(cutoff) && cutoff > 0)) {
    throw Error(ErrorCode::invalid_argument,
                "cutoff must be finite and > 0, got " + std::to_string(cutoff));
  }
}

double width_of(const Basis& basis, int axis) {
  const Vec side = cross(basis.unit[(axis + 1) % 3], basis.unit[(axis + 2) % 3]);
  return basis.length[axis] * std::abs(basis.det) / std::sqrt(dot(side, side));
}

}  // namespace

void validate(const Box& box) {
  effective_basis(box);
}

double face_width(const Box& box, int axis) {
  require_axis(axis);
  const Basis basis = effective_basis(box);
  if (!box.pbc[axis]) return std::numeric_limits<double>::infinity();
  return width_of(basis, axis);
}

bool minimum_image_ok(const Box& box, double cutoff) {
  require_cutoff(cutoff);
  const Basis basis = effective_basis(box);
  for (int k = 0; k < 3; ++k) {
    if (box.pbc[k] && !(width_of(basis, k) >= 2 * cutoff)) return false;
  }
  return true;
}

std::array<int, 3> image_range(const Box& box, double cutoff) {
  require_cutoff(cutoff);
  const Basis basis = effective_basis(box);
  std::array<int, 3> range{0, 0, 0};
  for (int k = 0; k < 3; ++k) {
    if (!box.pbc[k]) continue;
    const double images = std::ceil(cutoff / width_of(basis, k));
    if (!(images <= double(1 << 30))) {
      char text[160];
      std::snprintf(text, sizeof text,
                    "cutoff %.17g needs %.3g images along %s (face width %.17g): the cell is "
                    "far too thin for the cutoff",
                    cutoff, images, row_names[k], width_of(basis, k));
      refuse(text);
    }
    range[k] = static_cast<int>(images);
  }
  return range;
}

std::array<std::array<double, 3>, 3> reciprocal_rows(const Box& box) {
  const Basis basis = effective_basis(box);
  std::array<std::array<double, 3>, 3> g{};
  for (int k = 0; k < 3; ++k) {
    // f_k = x . (e_i x e_j) / det(E) with E's rows e = length * unit.
    const Vec side = cross(basis.unit[(k + 1) % 3], basis.unit[(k + 2) % 3]);
    for (int c = 0; c < 3; ++c) g[k][c] = side[c] / basis.det / basis.length[k];
  }
  return g;
}

Wrapped wrap(const Box& box, const std::array<double, 3>& x) {
  const auto g = reciprocal_rows(box);
  for (int k = 0; k < 3; ++k) {
    if (!std::isfinite(x[k])) {
      throw Error(ErrorCode::invalid_argument, "wrap: position (" + std::to_string(x[0]) + ", " +
                                                   std::to_string(x[1]) + ", " +
                                                   std::to_string(x[2]) + ") is not finite");
    }
  }
  Wrapped out;
  out.x = x;
  constexpr double limit = 2147483648.0;  // 2^31
  for (int k = 0; k < 3; ++k) {
    if (!box.pbc[k]) continue;
    const double f = dot(x, g[k]);
    double shift = std::floor(f);
    if (f - shift >= 1) shift += 1;  // f tiny and negative: f + 1 rounds to 1
    if (!(shift >= -limit && shift < limit)) {
      char text[200];
      std::snprintf(text, sizeof text,
                    "wrap: position (%.17g, %.17g, %.17g) lies %.3g cells away along %s, "
                    "beyond the int32 range of a shift",
                    x[0], x[1], x[2], f, row_names[k]);
      throw Error(ErrorCode::invalid_argument, text);
    }
    out.shift[k] = static_cast<std::int32_t>(shift);
  }
  for (int k = 0; k < 3; ++k) {
    if (out.shift[k] == 0) continue;
    for (int c = 0; c < 3; ++c) out.x[c] -= out.shift[k] * box.cell[k][c];
  }
  return out;
}

}  // namespace raycut
