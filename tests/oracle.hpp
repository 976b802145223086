// A double-precision oracle that does NOT share raycut's predicate (docs/limits.md):
// for float positions, |x_j - x_i|^2 is computed in double (each difference and square within
// 2^-52 relative of the real value, no underflow or overflow for any pair of finite floats) and
// every pair is classified as
//   in    d < C (1 - band)     the method must list it exactly once
//   out   d > C (1 + band)     the method must not list it
//   band  in between           either answer is accepted (float rounding may decide)
// with band = 1e-5, far wider than the float predicate's rounding (~3e-7 relative).
//
// The oracle only counts, per target, its in and band pairs: a list is then right iff it has no
// duplicate, no self pair, no out pair, and as many in pairs per row as the oracle counted.
// Counting is brute force below `brute_force_limit` particles and, above, a hash of cells of
// width ~C keyed by their double coordinates (written for the oracle alone: it does not use
// raycut's grid or cell code). Header-only, for the tests.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <sstream>
#include <string>
#include <unordered_map>
#include <vector>

#include "raycut/engine.hpp"

namespace raycut_test {

enum class PairClass { in, band, out };

struct DoubleOracle {
  std::vector<float> xyz;
  double cutoff = 0;
  double band = 1e-5;
  double in_below2 = 0, out_above2 = 0;       // (C (1 - band))^2, (C (1 + band))^2
  std::vector<std::uint32_t> in, band_count;  // per target
  std::uint64_t in_pairs = 0, band_pairs = 0;

  std::size_t size() const { return xyz.size() / 3; }

  double squared_distance(std::size_t i, std::size_t j) const {
    const double dx = static_cast<double>(xyz[3 * j]) - xyz[3 * i];
    const double dy = static_cast<double>(xyz[3 * j + 1]) - xyz[3 * i + 1];
    const double dz = static_cast<double>(xyz[3 * j + 2]) - xyz[3 * i + 2];
    return dx * dx + dy * dy + dz * dz;
  }
  PairClass classify(std::size_t i, std::size_t j) const {
    const double d2 = squared_distance(i, j);
    return d2 < in_below2 ? PairClass::in : d2 > out_above2 ? PairClass::out : PairClass::band;
  }
};

namespace oracle_detail {

inline void count_pair(const DoubleOracle& o, std::size_t i, std::size_t j, std::uint32_t& in,
                       std::uint32_t& band) {
  const double d2 = o.squared_distance(i, j);
  in += d2 < o.in_below2;
  band += d2 >= o.in_below2 && d2 <= o.out_above2;
}

inline void count_brute_force(DoubleOracle& o) {
  const std::size_t n = o.size();
#pragma omp parallel for schedule(dynamic, 64)
  for (std::size_t i = 0; i < n; ++i) {
    std::uint32_t in = 0, band = 0;
    for (std::size_t j = 0; j < n; ++j) {
      if (j != i) count_pair(o, i, j, in, band);
    }
    o.in[i] = in;
    o.band_count[i] = band;
  }
}

// Cells of width w = 1.001 C (1 + band), coordinates u = floor(x / w) in double. A pair that is
// in or in the band is at most w apart on each axis, so its cells differ by at most 1 on each
// axis (the double error of x / w is below 2^-12 where |u| < 2^40). Where |u| >= 2^40, adjacent
// floats are more than 2^16 w apart, so such a pair has exactly equal coordinates on that axis,
// hence equal u, and the axis is not searched (u + 1 would round to u there anyway).
using CellKey = std::array<double, 3>;
struct CellKeyHash {
  std::size_t operator()(const CellKey& k) const {
    std::size_t h = 0;
    for (double v : k) h = h * 1000003u ^ std::hash<double>{}(v);
    return h;
  }
};

inline void count_cells(DoubleOracle& o) {
  const std::size_t n = o.size();
  const double w = 1.001 * o.cutoff * (1 + o.band);
  std::vector<CellKey> key(n);
  std::unordered_map<CellKey, std::vector<std::uint32_t>, CellKeyHash> cells;
  for (std::size_t i = 0; i < n; ++i) {
    for (int a = 0; a < 3; ++a) key[i][a] = std::floor(static_cast<double>(o.xyz[3 * i + a]) / w);
    cells[key[i]].push_back(static_cast<std::uint32_t>(i));
  }
  std::vector<const std::vector<std::uint32_t>*> cell_list;
  std::vector<CellKey> cell_keys;
  for (const auto& [k, members] : cells) {
    cell_keys.push_back(k);
    cell_list.push_back(&members);
  }
#pragma omp parallel for schedule(dynamic, 16)
  for (std::size_t c = 0; c < cell_keys.size(); ++c) {
    const CellKey k = cell_keys[c];
    int reach[3];
    for (int a = 0; a < 3; ++a) reach[a] = std::fabs(k[a]) < 0x1p40 ? 1 : 0;
    for (std::uint32_t i : *cell_list[c]) {
      std::uint32_t in = 0, band = 0;
      for (int dz = -reach[2]; dz <= reach[2]; ++dz)
        for (int dy = -reach[1]; dy <= reach[1]; ++dy)
          for (int dx = -reach[0]; dx <= reach[0]; ++dx) {
            const auto it = cells.find({k[0] + dx, k[1] + dy, k[2] + dz});
            if (it == cells.end()) continue;
            for (std::uint32_t j : it->second) {
              if (j != i) count_pair(o, i, j, in, band);
            }
          }
      o.in[i] = in;
      o.band_count[i] = band;
    }
  }
}

}  // namespace oracle_detail

// The oracle of positions (N,3) and a cutoff C > 0.
inline DoubleOracle make_oracle(const std::vector<float>& xyz, float cutoff, double band = 1e-5,
                                std::size_t brute_force_limit = 20000) {
  DoubleOracle o;
  o.xyz = xyz;
  o.cutoff = cutoff;
  o.band = band;
  o.in_below2 = std::pow(o.cutoff * (1 - band), 2);
  o.out_above2 = std::pow(o.cutoff * (1 + band), 2);
  o.in.assign(o.size(), 0);
  o.band_count.assign(o.size(), 0);
  if (o.size() <= brute_force_limit)
    oracle_detail::count_brute_force(o);
  else
    oracle_detail::count_cells(o);
  for (std::size_t i = 0; i < o.size(); ++i) {
    o.in_pairs += o.in[i];
    o.band_pairs += o.band_count[i];
  }
  return o;
}

struct OracleCheck {
  bool ok = true;
  std::size_t bad_targets = 0;
  std::uint64_t listed = 0, listed_band = 0;  // entries in the list; of them, band pairs
  std::string first_problem;                  // empty when ok
  void fail(const std::string& what) {
    if (ok) first_problem = what;
    ok = false;
    ++bad_targets;
  }
};

// The first in pair of target i missing from `row` (sorted), by brute force: for messages.
inline std::string missing_in_pair(const DoubleOracle& o, std::size_t i,
                                   const std::vector<std::uint32_t>& row) {
  for (std::size_t j = 0; j < o.size(); ++j) {
    if (j != i && o.classify(i, j) == PairClass::in &&
        !std::binary_search(row.begin(), row.end(), static_cast<std::uint32_t>(j))) {
      std::ostringstream s;
      s.precision(9);
      s << "missing " << j << " (d / C = " << std::sqrt(o.squared_distance(i, j)) / o.cutoff << ")";
      return s.str();
    }
  }
  return "no in pair missing by brute force: the oracle's count is off";
}

// A CSR list (offsets N + 1, indices) against the oracle: every in pair exactly once, no out
// pair, no self pair, no duplicate; band pairs at most once.
inline OracleCheck check_list(const raycut::NeighbourList& list, const DoubleOracle& o) {
  OracleCheck r;
  const std::size_t n = o.size();
  if (list.offsets.size() != n + 1 || list.offsets.front() != 0 ||
      list.offsets.back() != list.indices.size()) {
    r.fail("malformed CSR: " + std::to_string(list.offsets.size()) + " offsets for N = " +
           std::to_string(n) + ", " + std::to_string(list.indices.size()) + " indices");
    return r;
  }
  r.listed = list.indices.size();
  std::vector<std::uint32_t> row;
  for (std::size_t i = 0; i < n; ++i) {
    if (list.offsets[i + 1] < list.offsets[i]) {
      r.fail("target " + std::to_string(i) + ": decreasing offsets");
      continue;
    }
    row.assign(list.indices.begin() + list.offsets[i], list.indices.begin() + list.offsets[i + 1]);
    std::sort(row.begin(), row.end());
    std::string problem;
    std::uint32_t in = 0;
    for (std::size_t k = 0; k < row.size() && problem.empty(); ++k) {
      const std::uint32_t j = row[k];
      if (j >= n) {
        problem = "index " + std::to_string(j) + " out of range";
      } else if (j == i) {
        problem = "itself listed";
      } else if (k > 0 && row[k - 1] == j) {
        problem = std::to_string(j) + " listed twice";
      } else {
        const PairClass c = o.classify(i, j);
        if (c == PairClass::out) {
          std::ostringstream s;
          s.precision(9);
          s << "out-of-range " << j
            << " listed (d / C = " << std::sqrt(o.squared_distance(i, j)) / o.cutoff << ")";
          problem = s.str();
        }
        in += c == PairClass::in;
        r.listed_band += c == PairClass::band;
      }
    }
    if (problem.empty() && in != o.in[i]) {
      problem = std::to_string(in) + " in pairs listed, oracle has " + std::to_string(o.in[i]) +
                "; " + missing_in_pair(o, i, row);
    }
    if (!problem.empty()) r.fail("target " + std::to_string(i) + ": " + problem);
  }
  return r;
}

// Per-target counts (the count kernel) against the oracle: in <= count <= in + band.
inline OracleCheck check_counts(const std::vector<std::uint32_t>& count, const DoubleOracle& o) {
  OracleCheck r;
  if (count.size() != o.size()) {
    r.fail(std::to_string(count.size()) + " counts for N = " + std::to_string(o.size()));
    return r;
  }
  for (std::size_t i = 0; i < count.size(); ++i) {
    r.listed += count[i];
    if (count[i] < o.in[i] || count[i] > o.in[i] + o.band_count[i]) {
      r.fail("target " + std::to_string(i) + ": count " + std::to_string(count[i]) + ", oracle: " +
             std::to_string(o.in[i]) + " in + " + std::to_string(o.band_count[i]) + " band");
    }
  }
  return r;
}

}  // namespace raycut_test
