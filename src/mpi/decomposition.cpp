// The decomposition (decomposition.hpp): geometry, cuts and balance of the spatial domains.
#include "mpi/decomposition.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <string>

#include "mpi/mpi_check.hpp"
#include "raycut/error.hpp"

namespace raycut::mpi {
namespace detail {
namespace {

// The unit vector of a row (zero stays zero).
std::array<double, 3> unit(const std::array<double, 3>& v) {
  const double norm = std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
  return norm > 0 ? std::array<double, 3>{v[0] / norm, v[1] / norm, v[2] / norm} : v;
}

double dot(const std::array<double, 3>& a, const std::array<double, 3>& b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

const char* axis_name(int axis) {
  return axis == 0 ? "x" : axis == 1 ? "y" : "z";
}

}  // namespace

void set_geometry(Decomposition& dec, const Box& box) {
  validate(box);
  const auto g = reciprocal_rows(box);
  dec.aligned = true;
  bool open_cartesian = true;  // every open e_k orthogonal to every periodic row
  for (int k = 0; k < 3; ++k) {
    dec.periodic[k] = box.pbc[k];
    for (int c = 0; c < 3; ++c) dec.cell[k][c] = box.cell[k][c];
    if (!box.pbc[k]) continue;
    for (int c = 0; c < 3; ++c) {
      if (c != k && box.cell[k][c] != 0) dec.aligned = false;
      if (c != k && !box.pbc[c] && box.cell[k][c] != 0) open_cartesian = false;
    }
    if (!(box.cell[k][k] > 0)) dec.aligned = false;
  }
  for (int k = 0; k < 3; ++k) {
    std::array<double, 3> e = {0, 0, 0};
    e[k] = 1;
    if (box.pbc[k] && dec.aligned) {
      dec.normal[k] = e;  // exactly: u_k = x_k, as orthorhombic boxes always had it
      dec.length[k] = box.cell[k][k];
    } else if (box.pbc[k]) {
      dec.normal[k] = unit(g[k]);
      dec.length[k] = face_width(box, k);
    } else {
      // The reciprocal row of a completion row is that row (unit, orthogonal to the others).
      dec.normal[k] = open_cartesian ? e : unit(g[k]);
      dec.length[k] = 0;
    }
  }
  dec.orthogonal = true;
  for (int a = 0; a < 3; ++a)
    for (int b = a + 1; b < 3; ++b)
      if (std::abs(dot(dec.normal[a], dec.normal[b])) > 1e-12) dec.orthogonal = false;
}

Domains domains_of(const Decomposition& dec) {
  Domains d{};
  for (int a = 0; a < 3; ++a) {
    d.dims[a] = dec.dims[a];
    d.periodic[a] = dec.periodic[a];
    d.images[a] = dec.images(a);
    d.crossed[a] = dec.halo_axis(a);
    d.length[a] = dec.length[a];
    for (int c = 0; c < 3; ++c) {
      d.normal[a][c] = dec.normal[a][c];
      d.cell[a][c] = dec.cell[a][c];
    }
    d.cuts[a] = dec.cuts[a].data();
  }
  d.aligned = dec.aligned;
  d.orthogonal = dec.orthogonal;
  return d;
}

double halo_reach(const Decomposition& dec, double halo_width) {
  double scale = halo_width;
  for (const auto& cuts : dec.cuts)
    for (double c : cuts) scale = std::max(scale, std::abs(c));
  return halo_width + 1e-5 * scale;
}

void set_equal_cuts(Decomposition& dec, const std::array<double, 6>& bounds, bool any_particles,
                    double halo_width) {
  for (int a = 0; a < 3; ++a) {
    double lo = 0;
    const double along = dot(dec.cell[a], dec.normal[a]);  // the open row's extent along u_a
    if (dec.periodic[a] || along > 0) {
      if (!dec.periodic[a]) dec.length[a] = along;
    } else {  // an open axis with no length: the particles' extent now
      lo = any_particles ? bounds[a] : 0;
      dec.length[a] = any_particles ? -bounds[3 + a] - bounds[a] : 0;
    }
    // Equal slabs; Balance::particles moves the inner cuts at the first exchange. Either way the
    // region must hold dims equal slabs of cutoff + skin.
    const double width = dec.length[a] / dec.dims[a];
    dec.cuts[a].resize(static_cast<std::size_t>(dec.dims[a]) + 1);
    for (int i = 0; i <= dec.dims[a]; ++i) dec.cuts[a][i] = lo + i * width;
    dec.cuts[a].back() = lo + dec.length[a];
    if (dec.halo_axis(a) && !(width >= halo_width)) {
      // Orthorhombic axes by coordinate, triclinic ones by cell row and face width.
      const std::string axis = dec.aligned ? axis_name(a)
                                           : std::string("cell row ") + "abc"[a] + " (normal " +
                                                 std::to_string(dec.normal[a][0]) + ", " +
                                                 std::to_string(dec.normal[a][1]) + ", " +
                                                 std::to_string(dec.normal[a][2]) + ")";
      throw Error(ErrorCode::invalid_argument,
                  "distributed engine: domains along " + axis + " are " + std::to_string(width) +
                      " wide (" + std::to_string(dec.dims[a]) + " over " +
                      (dec.periodic[a] ? "face width " : "") + std::to_string(dec.length[a]) +
                      "), less than cutoff + skin = " + std::to_string(halo_width) +
                      "; use fewer domains along that axis (DistributedOptions::dims) or a "
                      "larger box");
    }
  }
}

// Each axis by its own marginal distribution (the grid stays Cartesian, so every domain keeps its
// neighbours; docs/distributed.md says what this does not balance). Found by bisection, every cut
// at once, over MPI_Allreduce of the counts below the probes: integer sums and the same
// arithmetic, so every rank gets the same cuts. Then each slab is kept at least h = cutoff + skin
// wide, which the halo test needs (one image per side, neighbours' slabs only): cut i at least h
// above cut i - 1 and, on a periodic axis, h above 0 and at most L - (dims - i) h (room that the
// check of dims equal slabs leaves).
bool balance_cuts(Decomposition& dec, MPI_Comm comm, const std::vector<float>& xyz,
                  std::uint64_t global_size, double halo_width) {
  if (global_size == 0 || dec.domains() == 1) return false;
  const double inf = std::numeric_limits<double>::infinity();
  const std::size_t n = xyz.size() / 3;
  std::vector<double> u[3];
  std::array<double, 6> bounds = {inf, inf, inf, inf, inf, inf}, global;  // min, -max
  const Domains domains = domains_of(dec);
  for (int a = 0; a < 3; ++a) {
    if (dec.dims[a] == 1) continue;
    u[a].resize(n);
    for (std::size_t i = 0; i < n; ++i) {
      u[a][i] = domains.coordinate(a, &xyz[3 * i]);
      bounds[a] = std::min(bounds[a], u[a][i]);
      bounds[3 + a] = std::min(bounds[3 + a], -u[a][i]);
    }
    std::sort(u[a].begin(), u[a].end());
  }
  check(MPI_Allreduce(bounds.data(), global.data(), 6, MPI_DOUBLE, MPI_MIN, comm), "MPI_Allreduce");
  struct Cut {
    int axis, index;
    std::uint64_t target;  // particles below the cut
    double low, high;      // count(u < low) < target <= count(u < high)
  };
  std::vector<Cut> cuts;
  for (int a = 0; a < 3; ++a)
    for (int i = 1; i < dec.dims[a]; ++i)
      cuts.push_back({a, i, global_size * i / dec.dims[a], dec.periodic[a] ? 0.0 : global[a],
                      dec.periodic[a] ? dec.length[a] : -global[3 + a]});
  std::vector<std::uint64_t> below(cuts.size()), total(cuts.size());
  for (int round = 0; round < 48; ++round) {  // 2^-48 of the range: below float resolution
    for (std::size_t k = 0; k < cuts.size(); ++k) {
      const auto& v = u[cuts[k].axis];
      const double mid = 0.5 * (cuts[k].low + cuts[k].high);
      below[k] = static_cast<std::uint64_t>(std::lower_bound(v.begin(), v.end(), mid) - v.begin());
    }
    check(MPI_Allreduce(below.data(), total.data(), static_cast<int>(cuts.size()), MPI_UINT64_T,
                        MPI_SUM, comm),
          "MPI_Allreduce");
    for (std::size_t k = 0; k < cuts.size(); ++k)
      (total[k] < cuts[k].target ? cuts[k].low : cuts[k].high) = 0.5 * (cuts[k].low + cuts[k].high);
  }
  for (const Cut& cut : cuts) {  // by axis, then index: cut i - 1 is placed before cut i
    const int a = cut.axis, i = cut.index, d = dec.dims[a];
    double c = cut.high;
    if (i > 1 || dec.periodic[a]) c = std::max(c, dec.cuts[a][i - 1] + halo_width);
    if (dec.periodic[a]) c = std::min(c, dec.length[a] - (d - i) * halo_width);
    dec.cuts[a][i] = c;
  }
  return true;
}

}  // namespace detail

// ---- Decomposition: one implementation, the exchange's (domains.hpp) --------------------------

double Decomposition::coordinate(int axis, const float* xyz) const {
  return detail::domains_of(*this).coordinate(axis, xyz);
}

int Decomposition::slab(int axis, double u) const {
  return detail::domains_of(*this).slab(axis, u);
}

int Decomposition::owner(const float* xyz) const {
  return detail::domains_of(*this).owner(xyz);
}

std::array<int, 3> Decomposition::coords(int domain) const {
  int c[3];
  detail::domains_of(*this).coords(domain, c);
  return {c[0], c[1], c[2]};
}

}  // namespace raycut::mpi
