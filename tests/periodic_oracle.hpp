// A double-precision oracle for periodic pairs (docs/periodic.md, "Semantics"), independent of src/
// (it uses no raycut function, only the fields of a box: cell[3][3] and pbc[3]).
//
// For float positions x (the caller's, possibly unwrapped), a cell (rows a, b, c) and pbc, it
// enumerates every triple (i, j, S), S an integer vector (0 on non-periodic axes), with
//   r = x_j - x_i + S . cell,  d = |r| computed in double,
// except (i, i, 0), and classifies it as
//   in    d < C (1 - band)     a list must hold it exactly once
//   band  otherwise, d <= C (1 + band)   either answer is accepted (at most once)
//   out   d > C (1 + band)     a list must not hold it
// with band = 1e-5 (relative), far wider than float rounding of the predicate.
//
// The images searched are derived per pair, not from wrapped positions: with g_k the reciprocal
// vectors of the periodic rows (g_k . row_m = delta_km for periodic k, m; g_k in the span of the
// periodic rows, so |g_k| = 1 / (face width along k)), r . g_k = (x_j - x_i) . g_k + S_k, and
// |r . g_k| <= |r| |g_k|. So every S with d <= R = C (1 + band) has
//   S_k in [-(x_j - x_i) . g_k - R |g_k|, -(x_j - x_i) . g_k + R |g_k|],
// searched with one more image on each side against rounding. This holds for any positions,
// however far unwrapped, and any cell thickness. The g_k come from the inverse Gram matrix of
// the periodic rows (not the cross products box.cpp uses).
//
// Two point sets (query points, docs/periodic.md): make_query_oracle gives the triples (q, p, S) of
// queries q and sources p, r = p - q + S . cell, with no self-exclusion (the sets differ, even
// where a query coincides with a source).
//
// Brute force over all (i, j): for the tests' small systems (up to a few hundred particles).
// Header-only, for the tests.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace raycut_test {

// (i, j, S0, S1, S2)
using PeriodicTriple = std::array<std::int64_t, 5>;

enum class ImageClass { in, band, out };

struct PeriodicOracle {
  // In double: float positions exactly, or float64 ones as given.
  std::vector<double> xyz;      // the particles; with query points, the queries (the i of triples)
  std::vector<double> sources;  // with query points, the sources (the j); else unused
  bool query = false;           // two point sets: no (i, i, 0) exclusion, j indexes `sources`
  double cell[3][3] = {};
  bool pbc[3] = {};
  double cutoff = 0;
  double band = 1e-5;
  double in_below2 = 0, out_above2 = 0;  // (C (1 - band))^2, (C (1 + band))^2
  // Per-pair cutoffs (raycut::PairCutoffs): (i, j, S) in range iff d < pair_cutoff(i, j), each
  // with its own band; `cutoff` is then the largest, where the enumeration reaches.
  std::function<double(std::int64_t, std::int64_t)> pair_cutoff;
  std::vector<PeriodicTriple> in, band_pairs;  // full list: sorted, every orientation

  std::size_t size() const { return xyz.size() / 3; }  // targets (rows)
  std::size_t source_count() const { return query ? sources.size() / 3 : size(); }
  const double* source_xyz() const { return query ? sources.data() : xyz.data(); }

  std::array<double, 3> vector(std::size_t i, std::size_t j, const std::int64_t s[3]) const {
    std::array<double, 3> r;
    const double* xj = source_xyz() + 3 * j;
    for (int c = 0; c < 3; ++c) {
      r[c] = static_cast<double>(xj[c]) - static_cast<double>(xyz[3 * i + c]);
      for (int m = 0; m < 3; ++m) r[c] += static_cast<double>(s[m]) * cell[m][c];
    }
    return r;
  }
  double squared_distance(const PeriodicTriple& t) const {
    const std::array<double, 3> r =
        vector(static_cast<std::size_t>(t[0]), static_cast<std::size_t>(t[1]), &t[2]);
    return r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
  }
  ImageClass classify(const PeriodicTriple& t) const {
    for (int k = 0; k < 3; ++k)
      if (!pbc[k] && t[2 + k] != 0) return ImageClass::out;
    if (!query && t[0] == t[1] && t[2] == 0 && t[3] == 0 && t[4] == 0) return ImageClass::out;
    const double d2 = squared_distance(t);
    double below2 = in_below2, above2 = out_above2;
    if (pair_cutoff) {
      const double c = pair_cutoff(t[0], t[1]);
      below2 = (c * (1 - band)) * (c * (1 - band));
      above2 = (c * (1 + band)) * (c * (1 + band));
    }
    return d2 < below2 ? ImageClass::in : d2 > above2 ? ImageClass::out : ImageClass::band;
  }
};

// The half-list orientation of docs/periodic.md: i < j, or i == j and S lexicographically positive.
inline bool half_orientation(const PeriodicTriple& t) {
  if (t[0] != t[1]) return t[0] < t[1];
  for (int k = 2; k < 5; ++k)
    if (t[k] != 0) return t[k] > 0;
  return false;
}

inline std::string triple_text(const PeriodicTriple& t) {
  std::ostringstream out;
  out << "(" << t[0] << ", " << t[1] << ", [" << t[2] << " " << t[3] << " " << t[4] << "])";
  return out.str();
}

namespace periodic_detail {

// Reciprocal vectors g_k of the periodic rows (zero on non-periodic axes), through the inverse
// of the Gram matrix G = P P^T of the p periodic rows P: g_k = sum_m (G^-1)_km P_m.
inline std::array<std::array<double, 3>, 3> reciprocal(const double cell[3][3], const bool pbc[3]) {
  int rows[3], p = 0;
  for (int k = 0; k < 3; ++k)
    if (pbc[k]) rows[p++] = k;
  double g[3][3] = {};
  for (int a = 0; a < p; ++a)
    for (int b = 0; b < p; ++b)
      for (int c = 0; c < 3; ++c) g[a][b] += cell[rows[a]][c] * cell[rows[b]][c];
  double inv[3][3] = {};
  if (p == 1) {
    if (!(g[0][0] > 0)) throw std::invalid_argument("periodic oracle: zero periodic row");
    inv[0][0] = 1 / g[0][0];
  } else if (p == 2) {
    const double det = g[0][0] * g[1][1] - g[0][1] * g[1][0];
    if (!(det > 1e-24 * g[0][0] * g[1][1]))
      throw std::invalid_argument("periodic oracle: singular cell");
    inv[0][0] = g[1][1] / det;
    inv[1][1] = g[0][0] / det;
    inv[0][1] = -g[0][1] / det;
    inv[1][0] = -g[1][0] / det;
  } else if (p == 3) {
    const double c00 = g[1][1] * g[2][2] - g[1][2] * g[2][1];
    const double c01 = g[1][2] * g[2][0] - g[1][0] * g[2][2];
    const double c02 = g[1][0] * g[2][1] - g[1][1] * g[2][0];
    const double det = g[0][0] * c00 + g[0][1] * c01 + g[0][2] * c02;
    if (!(det > 1e-24 * g[0][0] * g[1][1] * g[2][2]))
      throw std::invalid_argument("periodic oracle: singular cell");
    inv[0][0] = c00 / det;
    inv[1][0] = c01 / det;
    inv[2][0] = c02 / det;
    inv[0][1] = (g[0][2] * g[2][1] - g[0][1] * g[2][2]) / det;
    inv[1][1] = (g[0][0] * g[2][2] - g[0][2] * g[2][0]) / det;
    inv[2][1] = (g[0][1] * g[2][0] - g[0][0] * g[2][1]) / det;
    inv[0][2] = (g[0][1] * g[1][2] - g[0][2] * g[1][1]) / det;
    inv[1][2] = (g[0][2] * g[1][0] - g[0][0] * g[1][2]) / det;
    inv[2][2] = (g[0][0] * g[1][1] - g[0][1] * g[1][0]) / det;
  }
  std::array<std::array<double, 3>, 3> out{};
  for (int a = 0; a < p; ++a)
    for (int b = 0; b < p; ++b)
      for (int c = 0; c < 3; ++c) out[rows[a]][c] += inv[a][b] * cell[rows[b]][c];
  return out;
}

template <class BoxLike>
void set_box(PeriodicOracle& o, const BoxLike& box, double cutoff, double band) {
  for (int r = 0; r < 3; ++r) {
    o.pbc[r] = box.pbc[r];
    for (int c = 0; c < 3; ++c) o.cell[r][c] = box.cell[r][c];
  }
  o.cutoff = cutoff;
  o.band = band;
  o.in_below2 = (cutoff * (1 - band)) * (cutoff * (1 - band));
  o.out_above2 = (cutoff * (1 + band)) * (cutoff * (1 + band));
}

// Every (i, j, S) of the oracle's point sets, classified into o.in and o.band_pairs (sorted).
inline void enumerate(PeriodicOracle& o) {
  const auto g = reciprocal(o.cell, o.pbc);
  const double reach = o.cutoff * (1 + o.band);
  const std::size_t n = o.size(), m = o.source_count();
  const double* xs = o.source_xyz();
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t j = 0; j < m; ++j) {
      double d[3];
      for (int c = 0; c < 3; ++c)
        d[c] = static_cast<double>(xs[3 * j + c]) - static_cast<double>(o.xyz[3 * i + c]);
      std::int64_t lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
      for (int k = 0; k < 3; ++k) {
        if (!o.pbc[k]) continue;
        const double along = d[0] * g[k][0] + d[1] * g[k][1] + d[2] * g[k][2];
        const double half =
            reach * std::sqrt(g[k][0] * g[k][0] + g[k][1] * g[k][1] + g[k][2] * g[k][2]);
        lo[k] = static_cast<std::int64_t>(std::floor(-along - half)) - 1;
        hi[k] = static_cast<std::int64_t>(std::ceil(-along + half)) + 1;
      }
      PeriodicTriple t{static_cast<std::int64_t>(i), static_cast<std::int64_t>(j), 0, 0, 0};
      for (t[2] = lo[0]; t[2] <= hi[0]; ++t[2])
        for (t[3] = lo[1]; t[3] <= hi[1]; ++t[3])
          for (t[4] = lo[2]; t[4] <= hi[2]; ++t[4]) {
            switch (o.classify(t)) {
              case ImageClass::in:
                o.in.push_back(t);
                break;
              case ImageClass::band:
                o.band_pairs.push_back(t);
                break;
              case ImageClass::out:
                break;
            }
          }
    }
  }
  std::sort(o.in.begin(), o.in.end());
  std::sort(o.band_pairs.begin(), o.band_pairs.end());
}

}  // namespace periodic_detail

// `box`: anything with double cell[3][3] and bool pbc[3] (raycut::Box; only its fields are read).
// `Real`: float or double positions.
template <class Real, class BoxLike>
PeriodicOracle make_periodic_oracle(const std::vector<Real>& xyz, const BoxLike& box, double cutoff,
                                    double band = 1e-5) {
  PeriodicOracle o;
  o.xyz.assign(xyz.begin(), xyz.end());
  periodic_detail::set_box(o, box, cutoff, band);
  periodic_detail::enumerate(o);
  return o;
}

// Per-pair cutoffs: pair (i, j) within pair_cutoff(i, j), at most `largest`.
template <class Real, class BoxLike>
PeriodicOracle make_pair_cutoff_oracle(
    const std::vector<Real>& xyz, const BoxLike& box,
    std::function<double(std::int64_t, std::int64_t)> pair_cutoff, double largest,
    double band = 1e-5) {
  PeriodicOracle o;
  o.xyz.assign(xyz.begin(), xyz.end());
  periodic_detail::set_box(o, box, largest, band);
  o.pair_cutoff = std::move(pair_cutoff);
  periodic_detail::enumerate(o);
  return o;
}

// Float positions written as a braced list, {0, 0, 0, 0.5f, 0, 0}.
template <class BoxLike>
PeriodicOracle make_periodic_oracle(const std::vector<float>& xyz, const BoxLike& box,
                                    double cutoff, double band = 1e-5) {
  return make_periodic_oracle<float, BoxLike>(xyz, box, cutoff, band);
}

// Queries (targets, rows) against sources: triples (q, p, S), r = p - q + S . cell, every one
// with |r| < C, (q, p, 0) included when they coincide.
template <class Real, class BoxLike>
PeriodicOracle make_query_oracle(const std::vector<Real>& queries, const std::vector<Real>& sources,
                                 const BoxLike& box, double cutoff, double band = 1e-5) {
  PeriodicOracle o;
  o.xyz.assign(queries.begin(), queries.end());
  o.sources.assign(sources.begin(), sources.end());
  o.query = true;
  periodic_detail::set_box(o, box, cutoff, band);
  periodic_detail::enumerate(o);
  return o;
}

struct PeriodicCheck {
  bool ok = true;
  std::uint64_t listed = 0, listed_band = 0;  // entries; of them, band triples
  std::uint64_t missing = 0, duplicates = 0, out = 0, wrong_orientation = 0, bad_index = 0;
  std::string problems;  // the first few, one a line
  void fail(const std::string& what) {
    if (ok || std::count(problems.begin(), problems.end(), '\n') < 8) problems += what + "\n";
    ok = false;
  }
};

// A list of triples (i[p], j[p], shifts[3p .. 3p+2]) against the oracle. Full (half = false):
// every in triple exactly once, band triples at most once, nothing else (no out triple, no
// (i, i, 0), no shift on a non-periodic axis). Half: the same over the triples of the half
// orientation (half_orientation), and every listed triple in that orientation.
// With a query oracle, i indexes the queries and j the sources (full lists only).
template <class Index>
PeriodicCheck check_periodic_pairs(const PeriodicOracle& o, const std::vector<Index>& i,
                                   const std::vector<Index>& j,
                                   const std::vector<std::int32_t>& shifts, bool half) {
  PeriodicCheck check;
  if (i.size() != j.size() || shifts.size() != 3 * i.size()) {
    check.fail("list sizes differ: i " + std::to_string(i.size()) + ", j " +
               std::to_string(j.size()) + ", shifts " + std::to_string(shifts.size()) +
               " (3 per pair)");
    return check;
  }
  const auto n = static_cast<std::int64_t>(o.size());
  const auto m = static_cast<std::int64_t>(o.source_count());
  std::vector<PeriodicTriple> listed;
  listed.reserve(i.size());
  for (std::size_t p = 0; p < i.size(); ++p) {
    const PeriodicTriple t{static_cast<std::int64_t>(i[p]), static_cast<std::int64_t>(j[p]),
                           shifts[3 * p], shifts[3 * p + 1], shifts[3 * p + 2]};
    if (t[0] < 0 || t[0] >= n || t[1] < 0 || t[1] >= m) {
      ++check.bad_index;
      check.fail("index out of range in " + triple_text(t) + " (targets " + std::to_string(n) +
                 ", sources " + std::to_string(m) + ")");
      continue;
    }
    listed.push_back(t);
  }
  check.listed = listed.size();
  std::sort(listed.begin(), listed.end());
  for (std::size_t p = 0; p < listed.size(); ++p) {
    const PeriodicTriple& t = listed[p];
    if (p > 0 && listed[p - 1] == t) {
      ++check.duplicates;
      check.fail("listed more than once: " + triple_text(t));
      continue;
    }
    if (half && !half_orientation(t)) {
      ++check.wrong_orientation;
      check.fail("half list holds " + triple_text(t) +
                 ", not in the half orientation (i < j, or i == j and S lexicographically > 0)");
    }
    switch (o.classify(t)) {
      case ImageClass::in:
        break;
      case ImageClass::band:
        ++check.listed_band;
        break;
      case ImageClass::out: {
        ++check.out;
        std::ostringstream what;
        what.precision(17);
        bool open_shift = false;
        for (int k = 0; k < 3; ++k) open_shift |= !o.pbc[k] && t[2 + k] != 0;
        if (open_shift) {
          what << "shift on a non-periodic axis: " << triple_text(t);
        } else if (!o.query && t[0] == t[1] && t[2] == 0 && t[3] == 0 && t[4] == 0) {
          what << "self pair " << triple_text(t);
        } else {
          what << "out of range: " << triple_text(t)
               << " at d = " << std::sqrt(o.squared_distance(t)) << " (cutoff " << o.cutoff << ")";
        }
        check.fail(what.str());
        break;
      }
    }
  }
  for (const PeriodicTriple& t : o.in) {
    if (half && !half_orientation(t)) continue;
    if (!std::binary_search(listed.begin(), listed.end(), t)) {
      ++check.missing;
      std::ostringstream what;
      what.precision(17);
      what << "missing " << triple_text(t) << " at d = " << std::sqrt(o.squared_distance(t))
           << " (cutoff " << o.cutoff << ")";
      check.fail(what.str());
    }
  }
  return check;
}

// The sorted (i, j, S) of a CSR list with shifts (anything with offsets, indices and shifts).
template <class List>
std::vector<PeriodicTriple> list_triples(const List& list) {
  std::vector<PeriodicTriple> out;
  for (std::size_t i = 0; i + 1 < list.offsets.size(); ++i)
    for (std::uint64_t p = list.offsets[i]; p < list.offsets[i + 1]; ++p)
      out.push_back({static_cast<std::int64_t>(i), static_cast<std::int64_t>(list.indices[p]),
                     list.shifts[3 * p], list.shifts[3 * p + 1], list.shifts[3 * p + 2]});
  std::sort(out.begin(), out.end());
  return out;
}

// A full and a half list (with shifts) against the oracle, the full list's symmetry ((i, j, S)
// listed iff (j, i, -S) is, band pairs included) and the half list as exactly the full list's
// half orientation: the failures, one a line (empty when they pass).
template <class List>
std::string check_full_and_half(const PeriodicOracle& o, const List& full, const List& half) {
  std::string failures;
  for (const bool is_half : {false, true}) {
    const List& list = is_half ? half : full;
    std::vector<std::uint32_t> i, j;
    for (std::size_t r = 0; r + 1 < list.offsets.size(); ++r)
      for (std::uint64_t p = list.offsets[r]; p < list.offsets[r + 1]; ++p) {
        i.push_back(static_cast<std::uint32_t>(r));
        j.push_back(list.indices[p]);
      }
    const PeriodicCheck check = check_periodic_pairs(o, i, j, list.shifts, is_half);
    if (!check.ok) failures += (is_half ? "half list: " : "full list: ") + check.problems;
  }
  const std::vector<PeriodicTriple> f = list_triples(full), h = list_triples(half);
  std::vector<PeriodicTriple> expected_half;
  for (const PeriodicTriple& t : f) {
    const PeriodicTriple mirror{t[1], t[0], -t[2], -t[3], -t[4]};
    if (!std::binary_search(f.begin(), f.end(), mirror))
      failures += "one-sided: " + triple_text(t) + " without its mirror\n";
    if (half_orientation(t)) expected_half.push_back(t);
  }
  if (h != expected_half)
    failures += "the half list (" + std::to_string(h.size()) +
                " entries) is not the half orientation of the full list (" +
                std::to_string(expected_half.size()) + ")\n";
  return failures;
}

}  // namespace raycut_test
