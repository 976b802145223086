// Periodic boxes, batches of systems and query sets (docs/periodic.md, "Semantics") on every method
// that takes them (brute-force, cell-list, brute-force-gpu, grid), against the double-precision
// image oracle of tests/periodic_oracle.hpp, which enumerates images per pair and shares nothing
// with src/. Lists (with shifts, distances, vectors; full and half), the count and Lennard-Jones
// kernels, a caller's functor that takes the shift, independence of the order of particles and
// of systems, the errors of bad boxes, batches and query sets, and the methods that refuse them.
// Methods not available here (no GPU) are skipped with the reason.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <map>
#include <numeric>
#include <random>
#include <stdexcept>
#include <string>
#include <tuple>
#include <vector>

#include "error_helpers.hpp"
#include "method_availability.hpp"
#include "periodic_oracle.hpp"
#include "raycut/box.hpp"
#include "raycut/engine.hpp"
#include "raycut/kernels.hpp"
#include "raycut/pairs.hpp"
#include "raycut/tools/device_array.hpp"

namespace {

using raycut::Box;
using raycut::Engine;
using raycut::ErrorCode;
using raycut::Kernel;
using raycut::MemorySpace;
using raycut::NeighbourList;
using raycut::Systems;
using raycut_test::contains;
using raycut_test::error_message;
using raycut_test::make_periodic_oracle;
using raycut_test::make_query_oracle;
using raycut_test::PeriodicCheck;
using raycut_test::PeriodicOracle;
using raycut_test::PeriodicTriple;

// The methods that take Systems (the others refuse them: PeriodicUnsupported below).
const std::vector<std::string> methods = {"brute-force", "cell-list", "brute-force-gpu", "grid"};

using raycut_test::unavailable;

#define SKIP_UNAVAILABLE(method)                                 \
  do {                                                           \
    const std::string why_ = unavailable(method);                \
    if (!why_.empty()) GTEST_SKIP() << (method) << ": " << why_; \
  } while (0)

Box make_box(std::array<double, 9> rows, std::array<bool, 3> pbc = {true, true, true}) {
  Box box;
  for (int k = 0; k < 9; ++k) box.cell[k / 3][k % 3] = rows[k];
  for (int k = 0; k < 3; ++k) box.pbc[k] = pbc[k];
  return box;
}

double norm(const double v[3]) {
  return std::sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
}

// ---- inputs ----------------------------------------------------------------------------------

// A family of one system: a box, and how its particles are drawn. Fractional coordinates along
// the periodic rows in [0, 1) (or on the faces: multiples of 1/4 in [0, 1], exact in float for
// dyadic cells), along the non-periodic axes in [-0.5, 1.5) of `open_rows`; then moved by up to
// +-unwrap cells along each periodic row.
struct Family {
  std::string name;
  Box box;
  double cutoff = 1;
  std::size_t n = 0;
  std::array<std::array<double, 3>, 3> open_rows{};
  int unwrap = 0;
  bool faces = false;
};

// gtest prints parameters with this (else as raw bytes).
void PrintTo(const Family& f, std::ostream* os) {
  *os << f.name << " n=" << f.n << " cutoff=" << f.cutoff;
}

// The particles, and a length that bounds every coordinate once wrapped (for float tolerances).
std::vector<float> draw(const Family& f, std::uint64_t seed, double* length = nullptr) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0, 1), open(-0.5, 1.5);
  std::uniform_int_distribution<int> quarter(0, 4), far(-f.unwrap, f.unwrap);
  double rows[3][3];
  double extent = f.cutoff;
  for (int k = 0; k < 3; ++k) {
    for (int c = 0; c < 3; ++c) rows[k][c] = f.box.pbc[k] ? f.box.cell[k][c] : f.open_rows[k][c];
    extent += 1.5 * norm(rows[k]);
  }
  if (length) *length = extent;
  std::vector<float> xyz(3 * f.n);
  for (std::size_t i = 0; i < f.n; ++i) {
    double frac[3];
    for (int k = 0; k < 3; ++k) {
      if (!f.box.pbc[k])
        frac[k] = open(rng);
      else if (f.faces)
        frac[k] = quarter(rng) / 4.0;
      else
        frac[k] = unit(rng);
      if (f.box.pbc[k] && f.unwrap > 0) frac[k] += far(rng);
    }
    for (int c = 0; c < 3; ++c) {
      double x = 0;
      for (int k = 0; k < 3; ++k) x += frac[k] * rows[k][c];
      xyz[3 * i + c] = static_cast<float>(x);
    }
  }
  return xyz;
}

const double s3 = std::sqrt(3.0);

Family family(const std::string& name, Box box, std::size_t n, double cutoff = 1) {
  Family f;
  f.name = name;
  f.box = box;
  f.n = n;
  f.cutoff = cutoff;
  return f;
}

Box scaled(Box box, double s) {
  for (auto& row : box.cell)
    for (double& v : row) v *= s;
  return box;
}

// The box families: cubic, orthorhombic, triclinic (60 degrees, very skewed,
// left-handed), 0.3 C to 10 C wide, slabs and wires, faces, unwrapped by up to 1000 cells.
std::vector<Family> families() {
  std::vector<Family> out;
  out.push_back(family("cubic_3C", Box::orthorhombic(3, 3, 3), 150));
  out.push_back(family("cubic_1_5C", Box::orthorhombic(1.5, 1.5, 1.5), 60));  // < 2C: images
  out.push_back(family("orthorhombic", Box::orthorhombic(2.5, 4, 1.25), 80));
  out.push_back(family("hexagonal_60deg", make_box({2, 0, 0, 1, s3, 0, 0, 0, 1.75}), 70));
  const Box rhombohedral = make_box({1, 0, 0, 0.5, s3 / 2, 0, 0.5, s3 / 6, std::sqrt(2.0 / 3.0)});
  out.push_back(family("rhombohedral_60deg", scaled(rhombohedral, 1.8), 60));
  // a and b 9.7 degrees apart; face widths 0.14 C, 0.27 C and 0.75 C.
  const Box skewed = make_box({2, 0, 0, 3.5, 0.6, 0, -1.25, 1.5, 0.75});
  out.push_back(family("very_skewed", skewed, 40));
  out.push_back(family("left_handed", make_box({2.5, 0, 0, 0, 0, 1.75, 0.5, 2.25, 0}), 60));
  out.push_back(family("left_handed_triclinic",
                       make_box({1.2, 0.1, -0.2, 0.4, 1.1, 0.1, 0.3, -0.2, -0.95}), 30));
  out.push_back(family("cubic_0_3C", Box::orthorhombic(0.3, 0.3, 0.3), 4));
  out.push_back(family("thin_0_3C_axis", Box::orthorhombic(0.3, 2.5, 2.5), 30));
  out.push_back(family("cubic_10C", Box::orthorhombic(10, 10, 10), 400));
  // The same cell in other units: C = 0.37.
  out.push_back(family("hexagonal_60deg_c037",
                       scaled(make_box({2, 0, 0, 1, s3, 0, 0, 0, 1.75}), 0.37), 70, 0.37));
  Family slab =
      family("slab", make_box({1.5, 0, 0, 0.5, 1.75, 0, 0, 0, 0}, {true, true, false}), 60);
  slab.open_rows[2] = {0, 0, 4};
  out.push_back(slab);
  Family wire =
      family("wire", make_box({0, 0, 0, 0, 0, 0, 0.25, 0.125, 1.25}, {false, false, true}), 40);
  wire.open_rows[0] = {3, 0, 0};
  wire.open_rows[1] = {0, 3, 0};
  out.push_back(wire);
  // A non-periodic row that is not zero (the contract lets it be anything finite): no images along
  // it.
  Family mixed = family("mixed_open_row",
                        make_box({1.5, 0, 0, 1, 1, 0, 0, 0.5, 1.25}, {true, false, true}), 50);
  mixed.open_rows[1] = {0, 3, 0};
  out.push_back(mixed);
  Family faces = family("faces_cubic", Box::orthorhombic(2, 2, 2), 60);
  faces.faces = true;
  out.push_back(faces);
  Family faces_tri =
      family("faces_triclinic", make_box({2, 0, 0, 0.5, 1.5, 0, 0.25, 0.5, 1.25}), 50);
  faces_tri.faces = true;
  out.push_back(faces_tri);
  // On the faces and 1000 cells away, still exactly (multiples of 1/16 below 2^24 / 16).
  Family faces_far = faces_tri;
  faces_far.name = "faces_triclinic_unwrapped";
  faces_far.unwrap = 1000;
  out.push_back(faces_far);
  Family unwrapped = family("unwrapped_triclinic", scaled(rhombohedral, 1.3), 60);
  unwrapped.unwrap = 1000;
  out.push_back(unwrapped);
  Family unwrapped_slab = slab;
  unwrapped_slab.name = "unwrapped_slab";
  unwrapped_slab.unwrap = 1000;
  unwrapped_slab.n = 40;
  out.push_back(unwrapped_slab);
  // No periodic axis: through the Box overload, a box with a cell but no pbc has no images.
  Family open = family("open_box_with_cell",
                       make_box({3, 0, 0, 0, 3, 0, 0, 0, 3}, {false, false, false}), 60);
  open.open_rows = {{{2, 0, 0}, {0, 2, 0}, {0, 0, 2}}};
  out.push_back(open);
  return out;
}

// A batch of systems (one system: a batch of one), their concatenated points, and an oracle per
// system in the system's own indices.
struct System {
  std::string name;
  Box box;
  std::vector<float> xyz;      // sources (the particles)
  std::vector<float> queries;  // query points, when the batch has them
  double length = 1;           // bounds the wrapped coordinates
};

struct Batch {
  std::vector<System> systems;
  double cutoff = 1;
  bool query = false;
  bool shared_box = false;  // every system in Systems::box
  std::vector<float> xyz, queries;
  std::vector<std::uint64_t> offsets, query_offsets;
  std::vector<PeriodicOracle> oracles;

  void finish() {
    xyz.clear(), queries.clear(), oracles.clear();
    offsets = {0}, query_offsets = {0};
    for (const System& s : systems) {
      xyz.insert(xyz.end(), s.xyz.begin(), s.xyz.end());
      queries.insert(queries.end(), s.queries.begin(), s.queries.end());
      offsets.push_back(xyz.size() / 3);
      query_offsets.push_back(queries.size() / 3);
      oracles.push_back(query ? make_query_oracle(s.queries, s.xyz, s.box, cutoff)
                              : make_periodic_oracle(s.xyz, s.box, cutoff));
    }
  }
  std::size_t sources() const { return xyz.size() / 3; }
  std::size_t targets() const { return query ? queries.size() / 3 : sources(); }
  const std::vector<std::uint64_t>& target_offsets() const {
    return query ? query_offsets : offsets;
  }
  // What build() takes; a single system without offsets unless `as_batch`.
  Systems arguments(bool as_batch = true) const {
    Systems s;
    if (shared_box || systems.size() == 1)
      s.box = systems.front().box;
    else
      for (const System& sys : systems) s.boxes.push_back(sys.box);
    if (as_batch || systems.size() != 1) s.offsets = offsets;
    if (query) {
      static const float dummy[3] = {0, 0, 0};  // a non-null pointer for zero queries
      s.queries = {queries.empty() ? dummy : queries.data(), queries.size() / 3, MemorySpace::host};
      if (as_batch || systems.size() != 1) s.query_offsets = query_offsets;
    }
    return s;
  }
  void build(Engine& engine, bool as_batch = true) const {
    static const float dummy[3] = {0, 0, 0};
    engine.build({xyz.empty() ? dummy : xyz.data(), sources(), MemorySpace::host},
                 static_cast<float>(cutoff), arguments(as_batch));
  }
};

Batch one_system(const Family& f, std::uint64_t seed) {
  Batch b;
  b.cutoff = f.cutoff;
  System s;
  s.name = f.name;
  s.box = f.box;
  s.xyz = draw(f, seed, &s.length);
  b.systems.push_back(s);
  b.finish();
  return b;
}

// ---- what a list holds -----------------------------------------------------------------------

// Calls f(system, local i, local j, S, entry) for every entry of the list; entries whose source
// lies in another system than their target are counted and reported, not passed on.
template <class F>
void for_each_entry(const NeighbourList& l, const Batch& b, F&& f) {
  ASSERT_EQ(l.offsets.size(), b.targets() + 1);
  ASSERT_EQ(l.offsets.front(), 0u);
  ASSERT_EQ(l.offsets.back(), l.indices.size());
  ASSERT_EQ(l.shifts.size(), 3 * l.indices.size()) << "the list was asked for shifts";
  const auto& to = b.target_offsets();
  std::uint64_t crossing = 0;
  for (std::size_t s = 0; s < b.systems.size(); ++s) {
    for (std::uint64_t i = to[s]; i < to[s + 1]; ++i) {
      ASSERT_LE(l.offsets[i], l.offsets[i + 1]);
      for (std::uint64_t e = l.offsets[i]; e < l.offsets[i + 1]; ++e) {
        const std::uint64_t j = l.indices[e];
        if (j < b.offsets[s] || j >= b.offsets[s + 1]) {
          if (++crossing <= 5)
            ADD_FAILURE() << "pair crosses systems: target " << i << " of system " << s << " ("
                          << b.systems[s].name << "), source " << j;
          continue;
        }
        const std::int64_t shift[3] = {l.shifts[3 * e], l.shifts[3 * e + 1], l.shifts[3 * e + 2]};
        f(s, i - to[s], j - b.offsets[s], shift, e);
      }
    }
  }
  EXPECT_EQ(crossing, 0u);
}

// Every system's entries against its oracle: full, or half in the contract's orientation.
void expect_list(const NeighbourList& l, const Batch& b, bool half, const std::string& what) {
  std::vector<std::vector<std::uint64_t>> is(b.systems.size()), js(b.systems.size());
  std::vector<std::vector<std::int32_t>> ss(b.systems.size());
  ASSERT_NO_FATAL_FAILURE(for_each_entry(
      l, b,
      [&](std::size_t s, std::uint64_t i, std::uint64_t j, const std::int64_t* S, std::uint64_t) {
        is[s].push_back(i), js[s].push_back(j);
        for (int k = 0; k < 3; ++k) ss[s].push_back(static_cast<std::int32_t>(S[k]));
      }));
  for (std::size_t s = 0; s < b.systems.size(); ++s) {
    const PeriodicCheck c =
        raycut_test::check_periodic_pairs(b.oracles[s], is[s], js[s], ss[s], half);
    EXPECT_TRUE(c.ok) << what << (half ? ", half list" : ", full list") << ", system " << s << " ("
                      << b.systems[s].name << "): " << c.listed << " listed, " << c.missing
                      << " missing, " << c.duplicates << " duplicates, " << c.out
                      << " out of range, " << c.wrong_orientation << " misoriented\n"
                      << c.problems;
  }
}

// Distances and vectors of every entry against r = x_j - x_i + S . cell in double.
void expect_geometry(const NeighbourList& l, const Batch& b, const std::string& what) {
  ASSERT_EQ(l.distances.size(), l.indices.size());
  ASSERT_EQ(l.vectors.size(), 3 * l.indices.size());
  int failures = 0;
  ASSERT_NO_FATAL_FAILURE(for_each_entry(
      l, b,
      [&](std::size_t s, std::uint64_t i, std::uint64_t j, const std::int64_t* S, std::uint64_t e) {
        const std::array<double, 3> r = b.oracles[s].vector(i, j, S);
        const double d = std::sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
        // r in float from points of magnitude <= length (wrapped, or images of them): a few
        // roundings of 6e-8 length (2e-8 length seen on the CPU methods).
        const double tol = 3e-7 * b.systems[s].length;
        bool ok = std::fabs(l.distances[e] - d) <= tol + 1e-6 * d;
        for (int c = 0; c < 3; ++c) ok = ok && std::fabs(l.vectors[3 * e + c] - r[c]) <= tol;
        if (!ok && ++failures <= 5)
          ADD_FAILURE() << what << ", system " << b.systems[s].name << ": pair (" << i << ", " << j
                        << ", [" << S[0] << " " << S[1] << " " << S[2] << "]): distance "
                        << l.distances[e] << " vector (" << l.vectors[3 * e] << ", "
                        << l.vectors[3 * e + 1] << ", " << l.vectors[3 * e + 2] << "), want " << d
                        << " (" << r[0] << ", " << r[1] << ", " << r[2] << ")";
      }));
  EXPECT_EQ(failures, 0) << what;
}

// The entries as global triples (i, j, S), sorted; indices mapped through target_map and
// source_map (new index -> original) when given.
std::vector<PeriodicTriple> triples(const NeighbourList& l,
                                    const std::vector<std::uint32_t>* target_map = nullptr,
                                    const std::vector<std::uint32_t>* source_map = nullptr) {
  std::vector<PeriodicTriple> out;
  for (std::size_t i = 0; i + 1 < l.offsets.size(); ++i)
    for (std::uint64_t e = l.offsets[i]; e < l.offsets[i + 1]; ++e) {
      const std::uint32_t j = l.indices[e];
      out.push_back({target_map ? (*target_map)[i] : static_cast<std::int64_t>(i),
                     source_map ? (*source_map)[j] : static_cast<std::int64_t>(j), l.shifts[3 * e],
                     l.shifts[3 * e + 1], l.shifts[3 * e + 2]});
    }
  std::sort(out.begin(), out.end());
  return out;
}

// ---- kernels ---------------------------------------------------------------------------------

constexpr float lj_sigma_over_cutoff = 0.4f;

// count == the list's rows; lj and lj_forces per target against a double sum over the oracle's
// triples of the target, within a tolerance propagated from float r (targets with band triples,
// whose terms either method may take, or nearly coincident pairs are not compared).
void expect_kernels(Engine& engine, const Batch& b, const NeighbourList& full,
                    const std::string& what) {
  const std::size_t n = b.targets();
  const std::vector<std::uint32_t> count = engine.compute(Kernel::count).count;
  ASSERT_EQ(count.size(), n) << what;
  for (std::size_t i = 0; i < n; ++i)
    ASSERT_EQ(count[i], full.offsets[i + 1] - full.offsets[i]) << what << ": count of target " << i;

  raycut::KernelOptions options;
  options.lj_sigma = lj_sigma_over_cutoff * static_cast<float>(b.cutoff);
  options.lj_epsilon = 1.5f;
  const raycut::Results lj = engine.compute(Kernel::lj, options);
  const raycut::Results ljf = engine.compute(Kernel::lj_forces, options);
  ASSERT_EQ(lj.energy.size(), n);
  ASSERT_EQ(ljf.energy.size(), n);
  ASSERT_EQ(ljf.force.size(), 3 * n);
  ASSERT_EQ(ljf.virial.size(), 6 * n);
  const double eps = options.lj_epsilon, sigma = options.lj_sigma;
  const auto& to = b.target_offsets();
  int failures = 0;
  std::size_t compared = 0;
  for (std::size_t s = 0; s < b.systems.size(); ++s) {
    const PeriodicOracle& o = b.oracles[s];
    const double dr = 3e-7 * b.systems[s].length;  // what float r may be off by (as above)
    std::vector<bool> skip(o.size(), false);
    for (const PeriodicTriple& t : o.band_pairs) skip[t[0]] = true;
    std::vector<double> e(o.size()), te(o.size()), f(3 * o.size()), tf(o.size()), v(6 * o.size()),
        tv(o.size());
    for (const PeriodicTriple& t : o.in) {
      const std::array<double, 3> r = o.vector(t[0], t[1], &t[2]);
      const double r2 = r[0] * r[0] + r[1] * r[1] + r[2] * r[2], d = std::sqrt(r2);
      const std::size_t i = t[0];
      if (d < 0.1 * sigma) {  // (sigma / r)^12 > 1e12: not a float comparison any more
        skip[i] = true;
        continue;
      }
      const double s6 = std::pow(sigma * sigma / r2, 3);
      e[i] += 4 * eps * (s6 * s6 - s6);
      te[i] += 4 * eps * (s6 * s6 + s6) * 1e-5 + 4 * eps * (12 * s6 * s6 + 6 * s6) / d * dr;
      const double g = -24 * eps * s6 * (2 * s6 - 1) / r2;  // f_i = g r
      const double ag = 24 * eps * s6 * (2 * s6 + 1) / r2;
      for (int a = 0; a < 3; ++a) f[3 * i + a] += g * r[a];
      tf[i] += ag * (1e-5 * d + 15 * dr);
      const int pa[6] = {0, 1, 2, 0, 0, 1}, pb[6] = {0, 1, 2, 1, 2, 2};
      for (int k = 0; k < 6; ++k) v[6 * i + k] += -0.5 * r[pa[k]] * g * r[pb[k]];
      tv[i] += ag * d * (1e-5 * d + 16 * dr);
    }
    for (std::size_t li = 0; li < o.size(); ++li) {
      if (skip[li]) continue;
      ++compared;
      const std::size_t i = to[s] + li;
      // lj: every pair fully on both atoms; lj_forces: half on each.
      bool ok = std::fabs(lj.energy[i] - e[li]) <= te[li] + 1e-30 &&
                std::fabs(ljf.energy[i] - 0.5 * e[li]) <= 0.5 * te[li] + 1e-30;
      for (int a = 0; a < 3; ++a)
        ok = ok && std::fabs(ljf.force[3 * i + a] - f[3 * li + a]) <= tf[li] + 1e-30;
      for (int k = 0; k < 6; ++k)
        ok = ok && std::fabs(ljf.virial[6 * i + k] - v[6 * li + k]) <= tv[li] + 1e-30;
      if (!ok && ++failures <= 5)
        ADD_FAILURE() << what << ", system " << b.systems[s].name << ", target " << li
                      << ": energy " << lj.energy[i] << " / 2 x " << ljf.energy[i] << " want "
                      << e[li] << " +- " << te[li] << "; force (" << ljf.force[3 * i] << ", "
                      << ljf.force[3 * i + 1] << ", " << ljf.force[3 * i + 2] << ") want ("
                      << f[3 * li] << ", " << f[3 * li + 1] << ", " << f[3 * li + 2] << ") +- "
                      << tf[li] << "; virial xx " << ljf.virial[6 * i] << " want " << v[6 * li]
                      << " +- " << tv[li];
    }
  }
  EXPECT_EQ(failures, 0) << what;
  std::size_t band = 0;
  for (const PeriodicOracle& o : b.oracles) band += o.band_pairs.size();
  if (n > 0 && band == 0) {
    EXPECT_GT(compared, 0u) << what << ": no target compared";
  }
}

// Everything a built engine must hold for batch b.
// The padded matrix of each row's K nearest (PaddedOptions::nearest, CPU methods): the row's
// true count, and min(count, K) distinct entries of the list, nearest first by the oracle's
// double distance, none farther than an entry left out. Distances equal to ~1e-12 may come in
// either order here (the library rounds r's terms in another order than the oracle); the exact
// order of ties is tested in Python (test_torch_knn_periodic.py) on exactly tied inputs.
void expect_nearest(Engine& engine, const Batch& b, const NeighbourList& full, std::uint32_t k,
                    const std::string& what) {
  raycut::PaddedNeighbourBuffer padded;
  const raycut::PaddedOptions options{
      .k = std::max<std::uint32_t>(k, 1), .shifts = true, .nearest = true};
  if (engine.space() != MemorySpace::host) {
    const std::string m =
        error_message(ErrorCode::unsupported, [&] { engine.padded_neighbours(padded, options); });
    EXPECT_TRUE(contains(m, "nearest")) << what << ": " << m;
    return;
  }
  engine.padded_neighbours(padded, options);
  if (b.targets() == 0) return;
  const std::vector<std::uint32_t> counts = padded.counts_to_host(),
                                   matrix = padded.indices_to_host();
  const std::vector<std::int32_t> shifts = padded.shifts_to_host();
  const auto& to = b.target_offsets();
  const std::uint32_t width = options.k;
  for (std::size_t s = 0; s < b.systems.size(); ++s) {
    const PeriodicOracle& oracle = b.oracles[s];
    for (std::uint64_t i = to[s]; i < to[s + 1]; ++i) {
      // The row's entries in the full list, by (i, j, S) local to the system, with d^2.
      std::map<PeriodicTriple, double> in_row;
      for (std::uint64_t e = full.offsets[i]; e < full.offsets[i + 1]; ++e) {
        const PeriodicTriple t{static_cast<std::int64_t>(i - to[s]),
                               static_cast<std::int64_t>(full.indices[e] - b.offsets[s]),
                               full.shifts[3 * e], full.shifts[3 * e + 1], full.shifts[3 * e + 2]};
        in_row[t] = oracle.squared_distance(t);
      }
      ASSERT_EQ(counts[i], in_row.size()) << what << ": nearest count of target " << i;
      const std::uint32_t kept = std::min<std::uint32_t>(counts[i], width);
      double previous = 0, farthest_kept = 0;
      for (std::uint32_t c = 0; c < kept; ++c) {
        const std::uint64_t e = i * width + c;
        const PeriodicTriple t{
            static_cast<std::int64_t>(i - to[s]),
            static_cast<std::int64_t>(matrix[e]) - static_cast<std::int64_t>(b.offsets[s]),
            shifts[3 * e], shifts[3 * e + 1], shifts[3 * e + 2]};
        const auto found = in_row.find(t);
        ASSERT_NE(found, in_row.end()) << what << ": row " << i << " entry " << c
                                       << " is not one of its pairs (or is repeated)";
        EXPECT_GE(found->second, previous * (1 - 1e-12))
            << what << ": row " << i << " entry " << c << " is nearer than the one before";
        previous = found->second;
        farthest_kept = std::max(farthest_kept, found->second);
        in_row.erase(found);
      }
      for (const auto& [t, d2] : in_row)
        EXPECT_GE(d2, farthest_kept * (1 - 1e-12))
            << what << ": row " << i << " left out a nearer pair (j " << t[1] << ")";
      for (std::uint32_t c = kept; c < width; ++c)
        EXPECT_EQ(matrix[i * width + c], b.sources()) << what << ": padding of row " << i;
    }
  }
}

void expect_matches(Engine& engine, const Batch& b, const std::string& what) {
  ASSERT_EQ(engine.size(), b.targets()) << what;
  ASSERT_EQ(engine.sources(), b.sources()) << what;
  const NeighbourList full = engine.neighbours({false, true, true, true});
  ASSERT_NO_FATAL_FAILURE(expect_list(full, b, false, what));
  ASSERT_NO_FATAL_FAILURE(expect_geometry(full, b, what));
  if (!b.query) {
    // The half list is the full list halved: of (i, j, S) and (j, i, -S) the oriented one.
    const NeighbourList half = engine.neighbours({true, true, true, true});
    ASSERT_NO_FATAL_FAILURE(expect_list(half, b, true, what));
    ASSERT_NO_FATAL_FAILURE(expect_geometry(half, b, what));
    std::vector<PeriodicTriple> oriented;
    for (const PeriodicTriple& t : triples(full))
      if (raycut_test::half_orientation(t)) oriented.push_back(t);
    EXPECT_EQ(triples(half), oriented) << what << ": half list != full list halved";
    EXPECT_EQ(2 * half.indices.size(), full.indices.size()) << what;
    // any_row: the same pairs, each in the row of either particle (the grid's half stencil),
    // with the vector and S of its own row.
    const NeighbourList either = engine.neighbours(
        {.half = true, .distances = true, .vectors = true, .shifts = true, .any_row = true});
    ASSERT_NO_FATAL_FAILURE(expect_geometry(either, b, what + ", any_row"));
    std::vector<PeriodicTriple> either_oriented;
    for (const PeriodicTriple& t : triples(either))
      either_oriented.push_back(
          raycut_test::half_orientation(t) ? t : PeriodicTriple{t[1], t[0], -t[2], -t[3], -t[4]});
    std::sort(either_oriented.begin(), either_oriented.end());
    EXPECT_EQ(either_oriented, oriented) << what << ": any_row half list != full list halved";
  }
  ASSERT_NO_FATAL_FAILURE(expect_kernels(engine, b, full, what));

  // The padded matrix: the list's rows (a source once per image), and overflow reported.
  std::uint32_t largest = 0;
  for (std::size_t i = 0; i < b.targets(); ++i)
    largest = std::max<std::uint32_t>(largest, full.offsets[i + 1] - full.offsets[i]);
  raycut::PaddedNeighbourBuffer padded;
  const std::uint32_t k = std::max<std::uint32_t>(largest, 1);
  EXPECT_FALSE(engine.padded_neighbours(padded, {.k = k}).overflowed()) << what;
  if (b.targets() > 0) {
    const std::vector<std::uint32_t> counts = padded.counts_to_host(),
                                     matrix = padded.indices_to_host();
    ASSERT_EQ(counts.size(), b.targets());
    for (std::size_t i = 0; i < b.targets(); ++i) {
      std::vector<std::uint32_t> want(full.indices.begin() + full.offsets[i],
                                      full.indices.begin() + full.offsets[i + 1]);
      ASSERT_EQ(counts[i], want.size()) << what << ": padded count of target " << i;
      std::vector<std::uint32_t> row(matrix.begin() + i * k, matrix.begin() + i * k + counts[i]);
      std::sort(row.begin(), row.end());
      std::sort(want.begin(), want.end());
      ASSERT_EQ(row, want) << what << ": padded row " << i;
    }
  }
  if (largest >= 2) {
    const raycut::PaddedReport report = engine.padded_neighbours(padded, {.k = largest - 1});
    EXPECT_EQ(report.largest_count, largest) << what;
    EXPECT_GT(report.overflowed_rows, 0u) << what;
  }
  ASSERT_NO_FATAL_FAILURE(expect_nearest(engine, b, full, (largest + 1) / 2, what));
}

// The same systems with particles (and queries) permuted within each system and the systems in
// another order; the maps give each new index its original one.
struct Permuted {
  Batch batch;
  std::vector<std::uint32_t> source_map, target_map;
};

Permuted permute(const Batch& b, std::uint64_t seed, bool reorder_systems) {
  std::mt19937_64 rng(seed);
  std::vector<std::size_t> order(b.systems.size());
  std::iota(order.begin(), order.end(), 0);
  if (reorder_systems) {
    std::reverse(order.begin(), order.end());
    std::shuffle(order.begin(), order.end(), rng);
    if (order.size() > 1 && std::is_sorted(order.begin(), order.end()))
      std::swap(order.front(), order.back());
  }
  Permuted p;
  p.batch.cutoff = b.cutoff;
  p.batch.query = b.query;
  p.batch.shared_box = b.shared_box;
  auto shuffle_points = [&](const std::vector<float>& xyz, std::uint64_t first,
                            std::vector<float>& out, std::vector<std::uint32_t>& map) {
    std::vector<std::uint32_t> perm(xyz.size() / 3);
    std::iota(perm.begin(), perm.end(), 0u);
    std::shuffle(perm.begin(), perm.end(), rng);
    out.clear();
    for (std::uint32_t k : perm) {
      out.insert(out.end(), xyz.begin() + 3 * k, xyz.begin() + 3 * k + 3);
      map.push_back(static_cast<std::uint32_t>(first + k));
    }
  };
  for (std::size_t s : order) {
    System sys = b.systems[s];
    shuffle_points(b.systems[s].xyz, b.offsets[s], sys.xyz, p.source_map);
    if (b.query)
      shuffle_points(b.systems[s].queries, b.query_offsets[s], sys.queries, p.target_map);
    p.batch.systems.push_back(sys);
  }
  if (!b.query) p.target_map = p.source_map;
  // Concatenate without oracles: the permuted run is compared with the original's triples.
  for (const System& s : p.batch.systems) {
    p.batch.xyz.insert(p.batch.xyz.end(), s.xyz.begin(), s.xyz.end());
    p.batch.queries.insert(p.batch.queries.end(), s.queries.begin(), s.queries.end());
  }
  p.batch.offsets = {0}, p.batch.query_offsets = {0};
  for (const System& s : p.batch.systems) {
    p.batch.offsets.push_back(p.batch.offsets.back() + s.xyz.size() / 3);
    p.batch.query_offsets.push_back(p.batch.query_offsets.back() + s.queries.size() / 3);
  }
  return p;
}

// The full list of a permuted batch, mapped back, equals the original's (band triples included:
// every method decides a pair the same way, whatever the order).
void expect_order_independent(const std::string& method, const Batch& b,
                              const std::vector<PeriodicTriple>& original, bool reorder_systems,
                              const std::string& what) {
  const Permuted p = permute(b, 1234, reorder_systems);
  Engine engine(method);
  p.batch.build(engine);
  NeighbourList list = engine.neighbours({false, false, false, true});
  ASSERT_EQ(list.offsets.size(), p.batch.targets() + 1);
  EXPECT_EQ(triples(list, &p.target_map, &p.source_map), original)
      << what << ": the pairs depend on the order of "
      << (reorder_systems ? "particles and systems" : "particles");
  // The count kernel follows its targets.
  const std::vector<std::uint32_t> count = engine.compute(Kernel::count).count;
  ASSERT_EQ(count.size(), p.batch.targets());
  std::vector<std::uint32_t> by_original(count.size());
  for (std::size_t k = 0; k < count.size(); ++k) by_original[p.target_map[k]] = count[k];
  std::vector<std::uint32_t> want(count.size());
  for (const PeriodicTriple& t : original) ++want[t[0]];
  EXPECT_EQ(by_original, want) << what;
}

// ---- single systems --------------------------------------------------------------------------

const Batch& family_batch(const Family& f) {
  static std::map<std::string, Batch> cache;
  auto [it, inserted] = cache.try_emplace(f.name);
  if (inserted) it->second = one_system(f, std::hash<std::string>{}(f.name) % 100000 + 17);
  return it->second;
}

class PeriodicFamilies : public ::testing::TestWithParam<std::tuple<std::string, Family>> {};

TEST_P(PeriodicFamilies, ListsAndKernelsMatchTheImageOracle) {
  const auto& [method, f] = GetParam();
  SKIP_UNAVAILABLE(method);
  const Batch& b = family_batch(f);
  ASSERT_FALSE(b.oracles[0].in.empty()) << f.name << ": the family has no pairs";

  Engine engine(method);
  engine.build({b.xyz.data(), b.sources(), MemorySpace::host}, static_cast<float>(f.cutoff), f.box);
  ASSERT_NO_FATAL_FAILURE(expect_matches(engine, b, method + " " + f.name));
  const std::vector<PeriodicTriple> original =
      triples(engine.neighbours({false, false, false, true}));

  // The same system as a batch of one (offsets {0, N}) gives the same triples.
  Engine batched(method);
  b.build(batched, /*as_batch=*/true);
  EXPECT_EQ(triples(batched.neighbours({false, false, false, true})), original)
      << method << " " << f.name << ": offsets {0, N} changed the pairs";

  ASSERT_NO_FATAL_FAILURE(
      expect_order_independent(method, b, original, false, method + " " + f.name));
}

std::string family_test_name(const ::testing::TestParamInfo<PeriodicFamilies::ParamType>& info) {
  std::string name = std::get<0>(info.param) + "_" + std::get<1>(info.param).name;
  for (char& ch : name)
    if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
  return name;
}

INSTANTIATE_TEST_SUITE_P(Methods, PeriodicFamilies,
                         ::testing::Combine(::testing::ValuesIn(methods),
                                            ::testing::ValuesIn(families())),
                         family_test_name);

// ---- batches ---------------------------------------------------------------------------------

Family find_family(const std::string& name) {
  for (const Family& f : families())
    if (f.name == name) return f;
  throw std::invalid_argument("no family " + name);
}

System system_of(Family f, std::size_t n, std::uint64_t seed) {
  f.n = n;
  System s;
  s.name = f.name;
  s.box = f.box;
  s.xyz = draw(f, seed, &s.length);
  return s;
}

// Cubic, triclinic, slab, wire, open, faces, unwrapped, empty and one-particle systems, one box
// each; two share particle positions but not boxes, so a pair found in the wrong box shows.
const Batch& mixed_batch() {
  static const Batch batch = [] {
    Batch b;
    b.systems.push_back(system_of(find_family("cubic_1_5C"), 40, 1));
    b.systems.push_back(system_of(find_family("hexagonal_60deg"), 30, 2));
    System empty;
    empty.name = "empty";
    empty.box = Box::orthorhombic(2, 2, 2);
    b.systems.push_back(empty);
    b.systems.push_back(system_of(find_family("slab"), 30, 3));
    System one;  // self-images only: (0, 0, S) for the 6 S with |S| = 1, 0.7 C
    one.name = "one_particle_0_7C";
    one.box = Box::orthorhombic(0.7, 0.7, 0.7);
    one.xyz = {0.1f, 0.2f, 0.3f};
    b.systems.push_back(one);
    b.systems.push_back(system_of(find_family("wire"), 25, 4));
    System open;
    open.name = "open";
    open.xyz = system_of(find_family("cubic_1_5C"), 30, 5).xyz;  // same points, no images
    open.length = 4;
    b.systems.push_back(open);
    b.systems.push_back(system_of(find_family("very_skewed"), 20, 6));
    System lone;
    lone.name = "one_particle_open";
    lone.xyz = {5, 5, 5};
    b.systems.push_back(lone);
    b.systems.push_back(system_of(find_family("left_handed_triclinic"), 20, 7));
    b.systems.push_back(system_of(find_family("cubic_0_3C"), 3, 8));
    b.systems.push_back(system_of(find_family("unwrapped_triclinic"), 30, 9));
    b.systems.push_back(system_of(find_family("faces_triclinic"), 20, 10));
    empty.name = "empty_open";
    empty.box = Box::open();
    b.systems.push_back(empty);
    b.finish();
    return b;
  }();
  return batch;
}

// Systems of one shared box (Systems::box), at the same positions: pairs never cross them.
const Batch& shared_box_batch() {
  static const Batch batch = [] {
    Batch b;
    b.shared_box = true;
    const Family f = find_family("cubic_1_5C");
    const System s = system_of(f, 30, 21);
    for (int k = 0; k < 4; ++k) b.systems.push_back(s);
    b.systems[2].xyz.resize(3 * 10);
    b.systems[3].xyz.clear();
    b.finish();
    return b;
  }();
  return batch;
}

class PeriodicBatch : public ::testing::TestWithParam<std::string> {};

TEST_P(PeriodicBatch, MixedSystemsMatchTheirOracles) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  const Batch& b = mixed_batch();
  Engine engine(method);
  b.build(engine);
  ASSERT_NO_FATAL_FAILURE(expect_matches(engine, b, method + " mixed batch"));
  const std::vector<PeriodicTriple> original =
      triples(engine.neighbours({false, false, false, true}));
  ASSERT_NO_FATAL_FAILURE(
      expect_order_independent(method, b, original, true, method + " mixed batch"));
}

TEST_P(PeriodicBatch, OneBoxForEverySystem) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  const Batch& b = shared_box_batch();
  Engine engine(method);
  b.build(engine);
  ASSERT_NO_FATAL_FAILURE(expect_matches(engine, b, method + " shared box"));
  // The two identical systems have identical rows, shifted by 30 indices.
  const NeighbourList l = engine.neighbours({false, false, false, true});
  std::vector<PeriodicTriple> first, second;
  for (const PeriodicTriple& t : triples(l)) {
    if (t[0] < 30) first.push_back(t);
    if (t[0] >= 30 && t[0] < 60) second.push_back({t[0] - 30, t[1] - 30, t[2], t[3], t[4]});
  }
  EXPECT_EQ(first, second);
  EXPECT_FALSE(first.empty());
}

INSTANTIATE_TEST_SUITE_P(Methods, PeriodicBatch, ::testing::ValuesIn(methods),
                         [](const auto& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

// ---- query sets ------------------------------------------------------------------------------

System query_system(const std::string& family_name, std::size_t sources, std::size_t queries,
                    std::uint64_t seed) {
  Family f = find_family(family_name);
  System s = system_of(f, sources, seed);
  f.n = queries;
  s.queries = draw(f, seed + 1000);
  // A query on a source, one on a face and, in periodic boxes, one far unwrapped: the
  // coincident pair (q, p, 0) is a pair (no self-exclusion between the sets).
  if (queries > 0 && sources > 0) std::copy(s.xyz.begin(), s.xyz.begin() + 3, s.queries.begin());
  if (queries > 1 && s.box.periodic())
    for (int c = 0; c < 3; ++c) s.queries[3 + c] = static_cast<float>(s.box.cell[0][c]);
  if (queries > 2 && s.box.pbc[0] && s.box.pbc[1] && s.box.pbc[2])
    for (int c = 0; c < 3; ++c)
      s.queries[6 + c] =
          static_cast<float>(s.queries[6 + c] + 700 * s.box.cell[0][c] - 300 * s.box.cell[2][c]);
  return s;
}

const Batch& query_single() {
  static const Batch batch = [] {
    Batch b;
    b.query = true;
    b.systems.push_back(query_system("rhombohedral_60deg", 60, 40, 31));
    b.finish();
    return b;
  }();
  return batch;
}

const Batch& query_batch() {
  static const Batch batch = [] {
    Batch b;
    b.query = true;
    b.systems.push_back(query_system("cubic_1_5C", 30, 20, 41));
    b.systems.push_back(query_system("very_skewed", 15, 10, 42));
    b.systems.push_back(query_system("slab", 20, 0, 43));  // sources, no queries
    b.systems.push_back(query_system("wire", 0, 12, 44));  // queries, no sources
    b.systems.push_back(query_system("cubic_0_3C", 2, 3, 45));
    System open = query_system("cubic_1_5C", 20, 15, 46);
    open.name = "open";
    open.box = Box::open();
    b.systems.push_back(open);
    b.systems.push_back(query_system("unwrapped_triclinic", 25, 20, 47));
    b.finish();
    return b;
  }();
  return batch;
}

class PeriodicQueries : public ::testing::TestWithParam<std::string> {};

TEST_P(PeriodicQueries, OneSystemMatchesTheQueryOracle) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  const Batch& b = query_single();
  EXPECT_TRUE(std::binary_search(b.oracles[0].in.begin(), b.oracles[0].in.end(),
                                 PeriodicTriple{0, 0, 0, 0, 0}))
      << "the query on source 0 must be its neighbour";
  Engine engine(method);
  b.build(engine, /*as_batch=*/false);
  ASSERT_NO_FATAL_FAILURE(expect_matches(engine, b, method + " queries"));
  const std::vector<PeriodicTriple> original =
      triples(engine.neighbours({false, false, false, true}));
  ASSERT_NO_FATAL_FAILURE(
      expect_order_independent(method, b, original, false, method + " queries"));
}

TEST_P(PeriodicQueries, BatchedWithQueryOffsets) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  const Batch& b = query_batch();
  Engine engine(method);
  b.build(engine);
  ASSERT_NO_FATAL_FAILURE(expect_matches(engine, b, method + " query batch"));
  const std::vector<PeriodicTriple> original =
      triples(engine.neighbours({false, false, false, true}));
  ASSERT_NO_FATAL_FAILURE(
      expect_order_independent(method, b, original, true, method + " query batch"));
}

INSTANTIATE_TEST_SUITE_P(Methods, PeriodicQueries, ::testing::ValuesIn(methods),
                         [](const auto& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

// ---- a caller's functor that takes the shift ---------------------------------------------------

// Records every (i, j, S) and r it is called with, per target.
struct RecordPairs {
  struct Entry {
    std::uint32_t j;
    raycut::Shift s;
    raycut::Vec3 r;
    float r2;
  };
  using Accumulator = std::vector<Entry>;
  std::vector<Accumulator>* rows;
  void operator()(Accumulator& acc, std::uint32_t, std::uint32_t j, raycut::Vec3 r, float r2,
                  const raycut::Shift& s) const {
    acc.push_back({j, s, r, r2});
  }
  void finish(std::uint32_t i, Accumulator& acc) const { (*rows)[i] = std::move(acc); }
};

static_assert(raycut::takes_shift<RecordPairs>::value);

// ... and takes only the pairs whose shift is lexicographically positive or zero with i < j:
// accepts() sees the shift too.
struct HalfByShift : RecordPairs {
  using options = raycut::functor_options<raycut::option::accepts>;
  bool accepts(std::uint32_t i, std::uint32_t j, const raycut::Shift& s) const {
    return i != j ? i < j : s.positive();
  }
};

class PeriodicFunctor : public ::testing::TestWithParam<std::string> {};

TEST_P(PeriodicFunctor, ReceivesTheListsTriplesAndVectors) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  for (const Batch* b :
       {&family_batch(find_family("very_skewed")),
        &family_batch(find_family("unwrapped_triclinic")), &mixed_batch(), &query_batch()}) {
    Engine engine(method);
    b->build(engine);
    std::vector<RecordPairs::Accumulator> rows(b->targets());
    if (engine.space() != MemorySpace::host) {
      // GPU methods run functors through raycut::cuda::for_each_pair (nvcc): a clear refusal.
      const std::string m = error_message(
          ErrorCode::unsupported, [&] { raycut::for_each_pair(engine, RecordPairs{&rows}); });
      EXPECT_TRUE(contains(m, "cuda::for_each_pair")) << m;
      continue;
    }
    raycut::for_each_pair(engine, RecordPairs{&rows});
    NeighbourList from_functor;
    from_functor.offsets = {0};
    for (const auto& row : rows) {
      for (const RecordPairs::Entry& e : row) {
        from_functor.indices.push_back(e.j);
        from_functor.shifts.insert(from_functor.shifts.end(), {e.s.a, e.s.b, e.s.c});
        from_functor.vectors.insert(from_functor.vectors.end(), {e.r.x, e.r.y, e.r.z});
        from_functor.distances.push_back(std::sqrt(e.r2));
      }
      from_functor.offsets.push_back(from_functor.indices.size());
    }
    const std::string what =
        method + " functor, " + b->systems.front().name + (b->systems.size() > 1 ? " batch" : "");
    ASSERT_NO_FATAL_FAILURE(expect_list(from_functor, *b, false, what));
    ASSERT_NO_FATAL_FAILURE(expect_geometry(from_functor, *b, what));
    EXPECT_EQ(triples(from_functor), triples(engine.neighbours({false, false, false, true})))
        << what << ": the functor's pairs differ from the list's";

    if (!b->query) {
      std::vector<RecordPairs::Accumulator> half_rows(b->targets());
      raycut::for_each_pair(engine, HalfByShift{{&half_rows}});
      NeighbourList half;
      half.offsets = {0};
      for (const auto& row : half_rows) {
        for (const RecordPairs::Entry& e : row) {
          half.indices.push_back(e.j);
          half.shifts.insert(half.shifts.end(), {e.s.a, e.s.b, e.s.c});
        }
        half.offsets.push_back(half.indices.size());
      }
      ASSERT_NO_FATAL_FAILURE(expect_list(half, *b, true, what + " accepts(i, j, S)"));
    }
  }
}

INSTANTIATE_TEST_SUITE_P(Methods, PeriodicFunctor, ::testing::ValuesIn(methods),
                         [](const auto& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

// ---- valid edge cases ------------------------------------------------------------------------

class PeriodicEdgeCases : public ::testing::TestWithParam<std::string> {};

TEST_P(PeriodicEdgeCases, NoParticles) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  static const float dummy[3] = {0, 0, 0};
  Engine engine(method);
  engine.build({dummy, 0, MemorySpace::host}, 1.0f, Box::orthorhombic(0.5, 0.5, 0.5));
  EXPECT_EQ(engine.size(), 0u);
  NeighbourList l = engine.neighbours({false, true, true, true});
  EXPECT_EQ(l.offsets, std::vector<std::uint64_t>{0});
  EXPECT_TRUE(l.indices.empty() && l.shifts.empty());
  EXPECT_TRUE(engine.compute(Kernel::count).count.empty());
  // A batch of empty systems.
  Systems empty;
  empty.boxes = {Box::orthorhombic(1, 1, 1), Box::open(), Box::orthorhombic(0.3, 0.3, 0.3)};
  empty.offsets = {0, 0, 0, 0};
  engine.build({dummy, 0, MemorySpace::host}, 1.0f, empty);
  EXPECT_EQ(engine.neighbours({false, false, false, true}).offsets, std::vector<std::uint64_t>{0});
}

TEST_P(PeriodicEdgeCases, QueriesWithoutSourcesAndSourcesWithoutQueries) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  static const float dummy[3] = {0, 0, 0};
  const std::vector<float> points = {0.1f, 0.2f, 0.3f, 0.5f, 0.5f, 0.5f, 0.9f, 0.1f, 0.4f};
  Systems s = Systems::periodic(Box::orthorhombic(1, 1, 1));
  s.queries = {points.data(), 3, MemorySpace::host};
  Engine engine(method);
  engine.build({dummy, 0, MemorySpace::host}, 0.8f, s);
  EXPECT_EQ(engine.size(), 3u);
  EXPECT_EQ(engine.sources(), 0u);
  NeighbourList l = engine.neighbours({false, false, false, true});
  EXPECT_EQ(l.offsets, (std::vector<std::uint64_t>{0, 0, 0, 0}));
  EXPECT_EQ(engine.compute(Kernel::count).count, (std::vector<std::uint32_t>{0, 0, 0}));

  s.queries = {dummy, 0, MemorySpace::host};
  engine.build({points.data(), 3, MemorySpace::host}, 0.8f, s);
  EXPECT_EQ(engine.size(), 0u);
  EXPECT_EQ(engine.sources(), 3u);
  EXPECT_EQ(engine.neighbours({false, false, false, true}).offsets, std::vector<std::uint64_t>{0});
}

TEST_P(PeriodicEdgeCases, OneParticleInATinyBoxHasOnlySelfImages) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  // Cube 0.45 C: self-images with 0.45 |S| < 1, |S|^2 <= 4: 6 + 12 + 8 + 6 = 32.
  Batch b;
  b.systems.push_back(
      {"one_particle", Box::orthorhombic(0.45, 0.45, 0.45), {0.05f, 0.4f, 0.2f}, {}, 2});
  b.finish();
  ASSERT_EQ(b.oracles[0].in.size(), 32u);
  Engine engine(method);
  b.build(engine, false);
  ASSERT_NO_FATAL_FAILURE(expect_matches(engine, b, method + " one particle"));
  const NeighbourList half = engine.neighbours({true, false, false, true});
  EXPECT_EQ(half.indices.size(), 16u);
}

TEST_P(PeriodicEdgeCases, CoincidentParticles) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  // Three particles at one point, one elsewhere, box 1.5 C: the coincident pairs at d = 0 with
  // S = 0, and their images.
  Batch b;
  b.systems.push_back({"coincident",
                       Box::orthorhombic(1.5, 1.5, 1.5),
                       {0.7f, 0.7f, 0.7f, 0.7f, 0.7f, 0.7f, 0.7f, 0.7f, 0.7f, 0.2f, 1.4f, 0.9f},
                       {},
                       5});
  b.finish();
  for (std::int64_t i = 0; i < 3; ++i) {
    for (std::int64_t j = 0; j < 3; ++j) {
      if (i != j) {
        ASSERT_TRUE(std::binary_search(b.oracles[0].in.begin(), b.oracles[0].in.end(),
                                       PeriodicTriple{i, j, 0, 0, 0}));
      }
    }
  }
  Engine engine(method);
  b.build(engine, false);
  const NeighbourList full = engine.neighbours({false, true, true, true});
  ASSERT_NO_FATAL_FAILURE(expect_list(full, b, false, method + " coincident"));
  ASSERT_NO_FATAL_FAILURE(expect_geometry(full, b, method + " coincident"));
  const NeighbourList half = engine.neighbours({true, false, false, true});
  ASSERT_NO_FATAL_FAILURE(expect_list(half, b, true, method + " coincident"));
  const std::vector<std::uint32_t> count = engine.compute(Kernel::count).count;
  for (std::size_t i = 0; i < 4; ++i) EXPECT_EQ(count[i], full.offsets[i + 1] - full.offsets[i]);
}

TEST_P(PeriodicEdgeCases, NoShiftsWithoutABox) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  // ListOptions::shifts without a box: zeros, one per entry.
  const std::vector<float> xyz = {0, 0, 0, 0.5f, 0, 0, 3, 0, 0};
  Engine engine(method);
  engine.build({xyz.data(), 3, MemorySpace::host}, 1.0f);
  const NeighbourList l = engine.neighbours({false, false, false, true});
  ASSERT_EQ(l.indices.size(), 2u);
  EXPECT_EQ(l.shifts, std::vector<std::int32_t>(6, 0));
}

// update() with new positions of the same particles: a rebuild over the same boxes and batch.
TEST_P(PeriodicEdgeCases, UpdateKeepsTheSystems) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  for (const char* name : {"very_skewed", "unwrapped_triclinic", "slab"}) {
    const Family f = find_family(name);
    const Batch& b = family_batch(f);
    const Batch moved = one_system(f, 999);
    Engine engine(method);
    engine.build({b.xyz.data(), b.sources(), MemorySpace::host}, static_cast<float>(f.cutoff),
                 f.box);
    engine.update({moved.xyz.data(), moved.sources(), MemorySpace::host});
    ASSERT_NO_FATAL_FAILURE(expect_list(engine.neighbours({false, false, false, true}), moved,
                                        false, method + " " + std::string(name) + " after update"));
  }
  // A batch: every system keeps its box (here the sources of each system reversed).
  const Batch& b = mixed_batch();
  Batch moved = b;
  for (System& s : moved.systems) {
    std::vector<float> reversed;
    for (std::size_t k = s.xyz.size() / 3; k-- > 0;)
      reversed.insert(reversed.end(), s.xyz.begin() + 3 * k, s.xyz.begin() + 3 * k + 3);
    s.xyz = reversed;
  }
  moved.finish();
  Engine engine(method);
  b.build(engine);
  engine.update({moved.xyz.data(), moved.sources(), MemorySpace::host});
  ASSERT_NO_FATAL_FAILURE(expect_list(engine.neighbours({false, false, false, true}), moved, false,
                                      method + " mixed batch after update"));
  // Query points are not kept beyond build(): update() refuses them (engine.hpp), build again.
  const Batch& q = query_batch();
  q.build(engine);
  const std::string m = error_message(ErrorCode::unsupported, [&] {
    engine.update({q.xyz.data(), q.sources(), MemorySpace::host});
  });
  EXPECT_TRUE(contains(m, "query")) << m;
}

// The padded matrix with shifts holds each row's (j, S) entries of the CSR list (a source once
// per image in a thin box), then padding with index N and S = 0; without shifts it has none.
TEST_P(PeriodicEdgeCases, PaddedRowsCarryShifts) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  for (const char* name : {"cubic_0_3C", "very_skewed", "slab"}) {
    const Family f = find_family(name);
    const Batch& b = family_batch(f);
    Engine engine(method);
    engine.build({b.xyz.data(), b.sources(), MemorySpace::host}, static_cast<float>(f.cutoff),
                 f.box);
    const NeighbourList l = engine.neighbours({false, false, false, true});
    const std::size_t n = b.sources();
    std::uint32_t k = 1;
    for (std::size_t i = 0; i < n; ++i)
      k = std::max<std::uint32_t>(k, static_cast<std::uint32_t>(l.offsets[i + 1] - l.offsets[i]));
    raycut::PaddedNeighbourBuffer padded;
    ASSERT_FALSE(engine.padded_neighbours(padded, {.k = k + 1, .shifts = true}).overflowed());
    const std::vector<std::uint32_t> idx = padded.indices_to_host();
    const std::vector<std::int32_t> sh = padded.shifts_to_host();
    ASSERT_EQ(sh.size(), 3 * idx.size()) << name;
    using Entry = std::array<std::int64_t, 4>;
    for (std::size_t i = 0; i < n; ++i) {
      std::vector<Entry> want, got;
      for (std::uint64_t e = l.offsets[i]; e < l.offsets[i + 1]; ++e)
        want.push_back({l.indices[e], l.shifts[3 * e], l.shifts[3 * e + 1], l.shifts[3 * e + 2]});
      for (std::uint32_t c = 0; c <= k; ++c) {
        const std::size_t e = i * (k + 1) + c;
        if (c < want.size())
          got.push_back({idx[e], sh[3 * e], sh[3 * e + 1], sh[3 * e + 2]});
        else
          EXPECT_EQ((Entry{idx[e], sh[3 * e], sh[3 * e + 1], sh[3 * e + 2]}),
                    (Entry{static_cast<std::int64_t>(n), 0, 0, 0}))
              << name << " padding of row " << i;
      }
      std::sort(want.begin(), want.end());
      std::sort(got.begin(), got.end());
      EXPECT_EQ(got, want) << method << " " << name << " row " << i;
    }
    ASSERT_FALSE(engine.padded_neighbours(padded, {.k = k + 1}).overflowed());
    EXPECT_EQ(padded.shifts(), nullptr);
    EXPECT_TRUE(padded.shifts_to_host().empty());
  }
}

INSTANTIATE_TEST_SUITE_P(Methods, PeriodicEdgeCases, ::testing::ValuesIn(methods),
                         [](const auto& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

// ---- errors ----------------------------------------------------------------------------------

class PeriodicErrors : public ::testing::TestWithParam<std::string> {};

TEST_P(PeriodicErrors, SingularCells) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  const std::vector<float> xyz = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f};
  Engine engine(method);
  for (const Box& box : {make_box({1, 0, 0, 2, 0, 0, 0, 0, 1}),     // b parallel to a
                         make_box({1, 0, 0, 1, 1e-8, 0, 0, 0, 1}),  // nearly so
                         make_box({1, 0, 0, 0, 1, 0, 1, 1, 0}),     // c in the a-b plane
                         make_box({1, 0, 0, 0, 0, 0, 0, 0, 1})}) {  // b zero
    const std::string m = error_message(ErrorCode::invalid_argument, [&] {
      engine.build({xyz.data(), 2, MemorySpace::host}, 1.0f, box);
    });
    EXPECT_TRUE(contains(m, "singular") || contains(m, "zero length")) << m;
  }
  // One bad box of a batch is refused too.
  Systems s;
  s.boxes = {Box::orthorhombic(1, 1, 1), make_box({1, 0, 0, 1, 1e-9, 0, 0, 0, 1})};
  s.offsets = {0, 1, 2};
  const std::string m = error_message(ErrorCode::invalid_argument, [&] {
    engine.build({xyz.data(), 2, MemorySpace::host}, 1.0f, s);
  });
  EXPECT_TRUE(contains(m, "singular")) << m;
}

// Device positions of a GPU method are checked in the image expansion's first pass (no check
// of their own): the first non-finite index is named, before one whose image shift would leave
// int32, and the engine builds again after the refusal.
TEST_P(PeriodicErrors, NonFiniteDevicePositionsNameTheirIndex) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  if (!raycut::cuda_device_available()) GTEST_SKIP() << "no CUDA device: no device positions";
  std::vector<float> xyz(3 * 40);
  for (std::size_t k = 0; k < xyz.size(); ++k) xyz[k] = 0.05f * static_cast<float>(k % 17);
  const Box box = Box::orthorhombic(1, 1, 1);
  Engine engine(method);
  xyz[3 * 2 + 1] = 3e30f;  // finite, more than 2^31 boxes away
  xyz[3 * 7 + 2] = std::numeric_limits<float>::quiet_NaN();
  xyz[3 * 31] = -std::numeric_limits<float>::infinity();
  std::string m = error_message(ErrorCode::invalid_input,
                                [&] { engine.build(raycut::DeviceArray(xyz).view(), 0.3f, box); });
  EXPECT_TRUE(contains(m, "non-finite coordinate at particle index 7")) << m;
  xyz[3 * 7 + 2] = 0.5f;
  xyz[3 * 31] = 0.5f;
  m = error_message(ErrorCode::invalid_argument,
                    [&] { engine.build(raycut::DeviceArray(xyz).view(), 0.3f, box); });
  EXPECT_TRUE(contains(m, "particle 2 ") && contains(m, "int32")) << m;
  xyz[3 * 2 + 1] = 0.5f;
  const raycut::DeviceArray good(xyz);
  engine.build(good.view(), 0.3f, box);
  EXPECT_EQ(engine.compute(Kernel::count).count.size(), 40u);
  xyz[3 * 9] = std::numeric_limits<float>::infinity();  // a step loop's update: the same check
  m = error_message(ErrorCode::invalid_input,
                    [&] { engine.update(raycut::DeviceArray(xyz).view()); });
  EXPECT_TRUE(contains(m, "non-finite coordinate at particle index 9")) << m;
}

TEST_P(PeriodicErrors, BadOffsets) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  const std::vector<float> xyz(3 * 6, 0.25f);
  Engine engine(method);
  // Each with a word of what is wrong.
  const std::vector<std::pair<std::vector<std::uint64_t>, std::string>> cases = {
      {{1, 6}, "must be 0"},
      {{0, 3, 5}, "end at"},
      {{0, 3, 7}, "end at"},
      {{0, 4, 2, 6}, "decreas"},
      {{0}, "2 entries"}};
  for (const auto& [offsets, problem] : cases) {
    Systems s = Systems::periodic(Box::orthorhombic(1, 1, 1));
    s.offsets = offsets;
    const std::string m = error_message(ErrorCode::invalid_argument, [&] {
      engine.build({xyz.data(), 6, MemorySpace::host}, 0.5f, s);
    });
    EXPECT_TRUE(contains(m, "offsets")) << m;
    EXPECT_TRUE(contains(m, problem)) << m;
  }
}

TEST_P(PeriodicErrors, BoxCountMatchesNeitherOneNorTheSystems) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  const std::vector<float> xyz(3 * 6, 0.25f);
  Engine engine(method);
  Systems s;
  s.offsets = {0, 2, 4, 6};
  s.boxes = {Box::orthorhombic(1, 1, 1), Box::orthorhombic(2, 2, 2)};
  std::string m = error_message(ErrorCode::invalid_argument, [&] {
    engine.build({xyz.data(), 6, MemorySpace::host}, 0.5f, s);
  });
  EXPECT_TRUE(contains(m, "boxes") && contains(m, "2") && contains(m, "3 systems")) << m;
  s.boxes.resize(4, Box::orthorhombic(1, 1, 1));
  m = error_message(ErrorCode::invalid_argument, [&] {
    engine.build({xyz.data(), 6, MemorySpace::host}, 0.5f, s);
  });
  EXPECT_TRUE(contains(m, "boxes") && contains(m, "4") && contains(m, "3 systems")) << m;
  // Several boxes without offsets: one system, so only one box fits.
  s.offsets.clear();
  s.boxes.resize(2);
  m = error_message(ErrorCode::invalid_argument, [&] {
    engine.build({xyz.data(), 6, MemorySpace::host}, 0.5f, s);
  });
  EXPECT_TRUE(contains(m, "boxes") && contains(m, "1 system")) << m;
  // One box for three systems is fine (it is every system's).
  s.offsets = {0, 2, 4, 6};
  s.boxes = {Box::orthorhombic(1, 1, 1)};
  EXPECT_NO_THROW(engine.build({xyz.data(), 6, MemorySpace::host}, 0.5f, s));
}

TEST_P(PeriodicErrors, QueryOffsetsMissingOrInconsistent) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  const std::vector<float> xyz(3 * 6, 0.25f), queries(3 * 4, 0.5f);
  Engine engine(method);
  Systems s = Systems::periodic(Box::orthorhombic(1, 1, 1));
  s.offsets = {0, 2, 6};
  s.queries = {queries.data(), 4, MemorySpace::host};
  for (const std::vector<std::uint64_t>& q :
       {std::vector<std::uint64_t>{},            // missing with a batch of 2
        std::vector<std::uint64_t>{0, 4},        // one system, not two
        std::vector<std::uint64_t>{0, 1, 2, 4},  // three
        std::vector<std::uint64_t>{0, 1, 3},     // not ending at M
        std::vector<std::uint64_t>{1, 2, 4},     // not starting at 0
        std::vector<std::uint64_t>{0, 3, 1, 4}}) {
    s.query_offsets = q;
    const std::string m = error_message(ErrorCode::invalid_argument, [&] {
      engine.build({xyz.data(), 6, MemorySpace::host}, 0.5f, s);
    });
    EXPECT_TRUE(contains(m, "query_offsets")) << m;
  }
  s.query_offsets = {0, 1, 4};
  EXPECT_NO_THROW(engine.build({xyz.data(), 6, MemorySpace::host}, 0.5f, s));
  EXPECT_EQ(engine.size(), 4u);
}

TEST_P(PeriodicErrors, HalfListWithQueryPoints) {
  const std::string& method = GetParam();
  SKIP_UNAVAILABLE(method);
  const std::vector<float> xyz(3 * 6, 0.25f), queries(3 * 4, 0.5f);
  Engine engine(method);
  Systems s = Systems::periodic(Box::orthorhombic(1, 1, 1));
  s.queries = {queries.data(), 4, MemorySpace::host};
  engine.build({xyz.data(), 6, MemorySpace::host}, 0.5f, s);
  const std::string m = error_message(ErrorCode::invalid_argument, [&] {
    engine.neighbours({/*half=*/true, false, false, false});
  });
  EXPECT_TRUE(contains(m, "half")) << m;
  EXPECT_TRUE(contains(m, "quer")) << m;
  raycut::NeighbourListBuffer buffer;
  EXPECT_TRUE(contains(error_message(ErrorCode::invalid_argument,
                                     [&] {
                                       engine.neighbours(buffer, {true, false, false, true});
                                     }),
                       "half"));
  // The full list still works after the refusal.
  EXPECT_EQ(engine.neighbours({false, false, false, true}).offsets.size(), 5u);
}

INSTANTIATE_TEST_SUITE_P(Methods, PeriodicErrors, ::testing::ValuesIn(methods),
                         [](const auto& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

// grid-paper and the OptiX methods have no images, batches or query points: every non-plain
// Systems is refused with Error(unsupported) naming the method, and plain builds still work.
TEST(PeriodicUnsupported, GridPaperAndOptixRefuseSystems) {
  const std::vector<float> xyz = {0.1f, 0.2f, 0.3f, 0.4f, 0.5f, 0.6f}, queries = {0, 0, 0};
  std::vector<Systems> refused(4);
  refused[0] = Systems::periodic(Box::orthorhombic(1, 1, 1));
  refused[1].offsets = {0, 1, 2};
  refused[2].queries = {queries.data(), 1, MemorySpace::host};
  refused[3] = Systems::periodic(make_box({1, 0, 0, 0, 0, 0, 0, 0, 0}, {true, false, false}));
  std::vector<std::string> skipped;
  int tried = 0;
  for (const auto& m : raycut::list_methods()) {
    if (m.name != "grid-paper" && m.name.rfind("optix", 0) != 0) continue;
    if (!m.available) {
      skipped.push_back(m.name + " (" + m.why_unavailable + ")");
      continue;
    }
    ++tried;
    Engine engine(m.name);
    for (const Systems& s : refused) {
      const std::string message = error_message(ErrorCode::unsupported, [&] {
        engine.build({xyz.data(), 2, MemorySpace::host}, 0.5f, s);
      });
      EXPECT_TRUE(contains(message, m.name)) << message;
    }
    EXPECT_NO_THROW(
        engine.build({xyz.data(), 2, MemorySpace::host}, 0.6f, Systems{}));  // |r| = 0.52
    EXPECT_EQ(engine.compute(Kernel::count).count, (std::vector<std::uint32_t>{1, 1}));
  }
  if (tried == 0) {
    std::string why;
    for (const std::string& s : skipped) why += " " + s;
    GTEST_SKIP() << "no grid-paper or optix method available:" << why;
  }
}

}  // namespace
