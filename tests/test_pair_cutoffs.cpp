// Per-pair cutoffs in the list pass (ListOptions::cutoffs): radii (c_ij = r_i + r_j) and species
// tables, against the double-precision image oracle (tests/periodic_oracle.hpp, which shares no
// code with src/) with each pair classified by its own cutoff. Random boxes with L / C from 1 to
// 10^6, skewed cells, partial pbc, positions unwrapped by up to 10^3 boxes, and partners placed
// within 1e-7 to 1e-2 of their own pair's cutoff; float32 and float64 positions; full and half
// lists, and the full list's symmetry. Then batches, open clouds, and every refusal.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "method_availability.hpp"
#include "periodic_oracle.hpp"
#include "raycut/box.hpp"
#include "raycut/engine.hpp"

namespace {

// Every method that takes boxes; those not available here (no GPU) are skipped by name.
const std::vector<std::string> box_methods = {"brute-force", "cell-list", "grid",
                                              "brute-force-gpu"};
// The methods whose search is exact at every L / C (docs/limits.md): fuzzed at every box size;
// the others at L / C <= 10^2, where their float band stays below the oracle's.
bool exact_search(const std::string& method) {
  return method == "brute-force" || method == "cell-list";
}

using raycut_test::unavailable;

struct Case {
  std::uint64_t seed = 0;
  raycut::Box box;
  std::vector<float> xyz;
  std::vector<double> xyz64;
  bool radii = false;                  // radii, else a species table
  std::vector<double> radius;          // per particle
  std::vector<std::uint32_t> species;  // per particle
  std::vector<double> table;           // kinds x kinds
  std::uint32_t kinds = 0;
  double largest = 0;  // the largest pair cutoff
  double ratio = 0;    // L / C
  std::string description;

  double cutoff(std::int64_t i, std::int64_t j) const {
    return radii ? radius[i] + radius[j] : table[species[i] * kinds + species[j]];
  }
  raycut::PairCutoffs cutoffs() const {
    raycut::PairCutoffs c;
    if (radii) {
      c.radii = radius.data();
    } else {
      c.species = species.data();
      c.table = table.data();
      c.kinds = kinds;
    }
    return c;
  }
};

// A random box, then particles in groups: a base, and partners at a distance near the cutoff of
// their own pair with the base (in, out, and within 1e-7 .. 1e-2 of it).
Case make_case(std::uint64_t seed, double max_ratio) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  Case c;
  c.seed = seed;
  c.radii = unit(rng) < 0.5;
  const double scale = std::ldexp(1.0 + unit(rng), static_cast<int>(unit(rng) * 8) - 4);
  c.kinds = 1 + static_cast<std::uint32_t>(unit(rng) * 3);
  std::vector<double> kind_radius(c.kinds);
  for (double& r : kind_radius) r = scale * (0.2 + 0.8 * unit(rng));
  c.table.assign(std::size_t{c.kinds} * c.kinds, 0);
  for (std::uint32_t a = 0; a < c.kinds; ++a)
    for (std::uint32_t b = 0; b <= a; ++b)
      c.table[a * c.kinds + b] = c.table[b * c.kinds + a] =
          unit(rng) < 0.1 ? 0.0 : scale * (0.3 + 1.2 * unit(rng));
  const double search = c.radii ? 2 * *std::max_element(kind_radius.begin(), kind_radius.end())
                                : *std::max_element(c.table.begin(), c.table.end());
  c.ratio = std::pow(max_ratio, unit(rng));
  const double length = c.ratio * std::max(search, scale);
  const int skew = static_cast<int>(unit(rng) * 3);
  for (int k = 0; k < 3; ++k) {
    const double side = length * (0.5 + unit(rng));
    c.box.cell[k][k] = side;
    for (int m = 0; m < k && skew > 0; ++m)
      c.box.cell[k][m] = (skew == 1 ? 0.3 : 0.9) * side * (2 * unit(rng) - 1);
    c.box.pbc[k] = unit(rng) < 0.8;
  }
  std::vector<std::array<double, 3>> points;
  const auto add = [&](const std::array<double, 3>& x, std::uint32_t kind) {
    points.push_back(x);
    c.species.push_back(kind);
    c.radius.push_back(kind_radius[kind]);
  };
  const int groups = 4 + static_cast<int>(unit(rng) * 8);
  for (int g = 0; g < groups; ++g) {
    std::array<double, 3> base{};
    for (int k = 0; k < 3; ++k) {
      const double u = unit(rng), f = u < 0.2 ? 0.0 : u < 0.35 ? 1.0 - 1e-9 : unit(rng);
      for (int d = 0; d < 3; ++d) base[d] += f * c.box.cell[k][d];
    }
    const auto base_kind = static_cast<std::uint32_t>(unit(rng) * c.kinds);
    add(base, base_kind);
    const int partners = 1 + static_cast<int>(unit(rng) * 5);
    for (int p = 0; p < partners; ++p) {
      const auto kind = static_cast<std::uint32_t>(unit(rng) * c.kinds);
      const double own = c.radii ? kind_radius[base_kind] + kind_radius[kind]
                                 : c.table[base_kind * c.kinds + kind];
      std::array<double, 3> dir{};
      double norm = 0;
      for (double& v : dir) {
        v = 2 * unit(rng) - 1;
        norm += v * v;
      }
      const double offset = (unit(rng) < 0.5 ? -1 : 1) * std::pow(10.0, -7 + 5 * unit(rng));
      const double d = unit(rng) < 0.2 ? own * unit(rng) : own * (1 + offset);
      std::array<double, 3> x{};
      for (int a = 0; a < 3; ++a) x[a] = base[a] + d * dir[a] / std::sqrt(norm);
      add(x, kind);
    }
  }
  const bool unwrapped = unit(rng) < 0.5;
  for (auto& x : points)
    for (int k = 0; k < 3 && unwrapped; ++k) {
      if (!c.box.pbc[k]) continue;
      const double n = std::round((2 * unit(rng) - 1) * (unit(rng) < 0.3 ? 1000 : 2));
      for (int d = 0; d < 3; ++d) x[d] += n * c.box.cell[k][d];
    }
  for (const auto& x : points)
    for (const double v : x) {
      c.xyz.push_back(static_cast<float>(v));
      c.xyz64.push_back(v);
    }
  c.largest = search;
  c.description = "seed " + std::to_string(seed) + ": " + (c.radii ? "radii" : "species table") +
                  ", L/C " + std::to_string(c.ratio) + ", skew " + std::to_string(skew) + ", pbc " +
                  std::to_string(c.box.pbc[0]) + std::to_string(c.box.pbc[1]) +
                  std::to_string(c.box.pbc[2]) + (unwrapped ? ", unwrapped" : "") + ", N " +
                  std::to_string(points.size());
  return c;
}

// The engine's search cutoff: the largest pair cutoff rounded up to a float, so that the search
// offers every pair the filter may keep (any cutoff when every pair cutoff is 0).
float search_cutoff(double largest) {
  if (largest == 0) return 1.0f;
  const auto c = static_cast<float>(largest);
  return static_cast<double>(c) >= largest ? c : std::nextafter(c, INFINITY);
}

// Failures of one case on one method (empty when it passes).
std::string run_case(const Case& c, const std::string& method, bool float64) {
  raycut::Engine engine(method);
  const float search = search_cutoff(c.largest);
  if (float64)
    engine.build(raycut::Float64Positions{c.xyz64.data(), c.xyz64.size() / 3}, search,
                 raycut::Systems::periodic(c.box));
  else
    engine.build({c.xyz.data(), c.xyz.size() / 3, raycut::MemorySpace::host}, search, c.box);
  const raycut::PairCutoffs cutoffs = c.cutoffs();
  const raycut::NeighbourList full = engine.neighbours({.shifts = true, .cutoffs = &cutoffs});
  const raycut::NeighbourList half =
      engine.neighbours({.half = true, .shifts = true, .cutoffs = &cutoffs});
  const auto pair_cutoff = [&c](std::int64_t i, std::int64_t j) { return c.cutoff(i, j); };
  const raycut_test::PeriodicOracle oracle =
      float64 ? raycut_test::make_pair_cutoff_oracle(c.xyz64, c.box, pair_cutoff, c.largest, 1e-6)
              : raycut_test::make_pair_cutoff_oracle(c.xyz, c.box, pair_cutoff, c.largest, 1e-6);
  return raycut_test::check_full_and_half(oracle, full, half);
}

class PairCutoffs : public ::testing::TestWithParam<std::string> {};

TEST_P(PairCutoffs, FuzzAgainstTheImageOracle) {
  const std::string& method = GetParam();
  if (const std::string why = unavailable(method); !why.empty())
    GTEST_SKIP() << method << ": " << why;
  const double max_ratio = exact_search(method) ? 1e6 : 1e2;
  std::size_t pairs = 0;
  for (std::uint64_t seed = 1; seed <= 150 && !HasFailure(); ++seed) {
    const Case c = make_case(seed, max_ratio);
    for (const bool float64 : {false, true}) {
      if (float64 && !exact_search(method)) continue;  // float64 positions: the CPU methods
      const std::string failures = run_case(c, method, float64);
      EXPECT_TRUE(failures.empty())
          << method << (float64 ? ", float64 positions" : "") << ", " << c.description << ":\n"
          << failures.substr(0, 2000);
    }
    pairs += c.xyz.size() / 3;
  }
  EXPECT_GT(pairs, 1000u);  // the cases are not empty
}

// Two systems in one batch, each with its own cell: the cutoffs index the batch's particles.
TEST_P(PairCutoffs, BatchWithACellPerSystem) {
  const std::string& method = GetParam();
  if (const std::string why = unavailable(method); !why.empty())
    GTEST_SKIP() << method << ": " << why;
  const Case a = make_case(7, 10), b = make_case(8, 10);
  Case all = a;  // radii from both (species tables differ between cases: radii here)
  all.radii = true;
  all.radius.insert(all.radius.end(), b.radius.begin(), b.radius.end());
  all.xyz.insert(all.xyz.end(), b.xyz.begin(), b.xyz.end());
  const std::size_t na = a.xyz.size() / 3, n = all.xyz.size() / 3;
  all.largest = 2 * *std::max_element(all.radius.begin(), all.radius.end());
  raycut::Systems systems;
  systems.boxes = {a.box, b.box};
  systems.offsets = {0, na, n};
  raycut::Engine engine(method);
  engine.build({all.xyz.data(), n, raycut::MemorySpace::host}, search_cutoff(all.largest), systems);
  const raycut::PairCutoffs cutoffs = all.cutoffs();
  const raycut::NeighbourList list = engine.neighbours({.shifts = true, .cutoffs = &cutoffs});
  for (int s = 0; s < 2; ++s) {
    const std::size_t first = s == 0 ? 0 : na, last = s == 0 ? na : n;
    const std::vector<float> xyz(all.xyz.begin() + 3 * first, all.xyz.begin() + 3 * last);
    const auto pair_cutoff = [&](std::int64_t i, std::int64_t j) {
      return all.radius[first + i] + all.radius[first + j];
    };
    const raycut_test::PeriodicOracle oracle = raycut_test::make_pair_cutoff_oracle(
        xyz, s == 0 ? a.box : b.box, pair_cutoff, all.largest, 1e-6);
    std::vector<std::uint32_t> i, j;
    std::vector<std::int32_t> shifts;
    for (std::size_t r = first; r < last; ++r)
      for (std::uint64_t p = list.offsets[r]; p < list.offsets[r + 1]; ++p) {
        ASSERT_GE(list.indices[p], first);
        ASSERT_LT(list.indices[p], last);
        i.push_back(static_cast<std::uint32_t>(r - first));
        j.push_back(static_cast<std::uint32_t>(list.indices[p] - first));
        shifts.insert(shifts.end(), &list.shifts[3 * p], &list.shifts[3 * p] + 3);
      }
    const raycut_test::PeriodicCheck check =
        raycut_test::check_periodic_pairs(oracle, i, j, shifts, false);
    EXPECT_TRUE(check.ok) << "system " << s << ":\n" << check.problems;
  }
}

// An open cloud (no box): d < r_i + r_j, with distances written as asked.
TEST_P(PairCutoffs, OpenCloudWithDistances) {
  const std::string& method = GetParam();
  if (const std::string why = unavailable(method); !why.empty())
    GTEST_SKIP() << method << ": " << why;
  // Particles on a line 1 apart: radii 0.3, 0.8, 0.3, 0.45 pair (0, 1) at 1.1 > 1, (1, 2)
  // likewise, (2, 3) at 0.75 < 1 (out), and (1, 3) at 1.25 < 2 (out).
  const std::vector<float> xyz = {0, 0, 0, 1, 0, 0, 2, 0, 0, 3, 0, 0};
  const std::vector<double> radius = {0.3, 0.8, 0.3, 0.45};
  raycut::Engine engine(method);
  engine.build({xyz.data(), 4, raycut::MemorySpace::host}, 1.6f);
  raycut::PairCutoffs cutoffs;
  cutoffs.radii = radius.data();
  const raycut::NeighbourList list =
      engine.neighbours({.distances = true, .coo = true, .cutoffs = &cutoffs});
  std::vector<std::array<std::int64_t, 2>> pairs;
  for (std::size_t p = 0; p < list.rows.size(); ++p) {
    pairs.push_back({list.rows[p], list.columns[p]});
    EXPECT_FLOAT_EQ(list.distances[p], 1.0f);
  }
  std::sort(pairs.begin(), pairs.end());
  const std::vector<std::array<std::int64_t, 2>> expected = {{0, 1}, {1, 0}, {1, 2}, {2, 1}};
  EXPECT_EQ(pairs, expected);
}

INSTANTIATE_TEST_SUITE_P(Methods, PairCutoffs, ::testing::ValuesIn(box_methods),
                         [](const auto& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

// Each refusal names what is wrong and what is accepted.
TEST(PairCutoffsRefusals, NameTheValueAndTheRange) {
  const std::vector<float> xyz = {0, 0, 0, 1, 0, 0, 0, 1, 0};
  raycut::Engine engine("cell-list");
  engine.build({xyz.data(), 3, raycut::MemorySpace::host}, 2.0f);
  const auto message = [&](const raycut::PairCutoffs& cutoffs) -> std::string {
    try {
      engine.neighbours({.cutoffs = &cutoffs});
    } catch (const raycut::Error& e) {
      EXPECT_EQ(e.code(), raycut::ErrorCode::invalid_argument);
      return e.what();
    }
    return "accepted";
  };
  const std::vector<double> negative = {0.5, -0.1, 0.5}, nan = {0.5, 0.5, NAN},
                            large = {0.5, 1.01, 0.5}, fine = {0.5, 1.0, 0.5};
  const std::vector<std::uint32_t> species = {0, 1, 2};
  const std::vector<double> asymmetric = {1, 0.5, 1, 1}, table = {1, 0.5, 0.5, 1};
  raycut::PairCutoffs c;
  c.radii = negative.data();
  EXPECT_NE(message(c).find("radius 1 is -0.1 (finite and >= 0 accepted)"), std::string::npos);
  c.radii = nan.data();
  EXPECT_NE(message(c).find("radius 2 is nan"), std::string::npos);
  c.radii = large.data();
  EXPECT_NE(message(c).find("a pair cutoff of 2.02 exceeds the engine's cutoff 2,"),
            std::string::npos);
  c.radii = fine.data();
  EXPECT_EQ(message(c), "accepted");  // 2 max r_i = 2: the engine's cutoff itself
  c.table = table.data();
  c.species = species.data();
  c.kinds = 2;
  EXPECT_NE(message(c).find("radii or a species table, not both"), std::string::npos);
  c.radii = nullptr;
  EXPECT_NE(message(c).find("particle 2 has species 2, outside the table's [0, 2)"),
            std::string::npos);
  const std::vector<std::uint32_t> two_kinds = {0, 1, 1};
  c.species = two_kinds.data();
  c.table = asymmetric.data();
  EXPECT_NE(message(c).find("not symmetric: [1][0] = 1, [0][1] = 0.5"), std::string::npos);
  c.kinds = 0;
  EXPECT_NE(message(c).find("kinds >= 1"), std::string::npos);
  c.table = table.data();
  c.kinds = 2;
  EXPECT_EQ(message(c), "accepted");

  // Query points: the cutoffs pair particles with each other.
  const std::vector<float> queries = {0.5f, 0, 0};
  raycut::Systems systems;
  systems.queries = {queries.data(), 1, raycut::MemorySpace::host};
  raycut::Engine query_engine("cell-list");
  query_engine.build({xyz.data(), 3, raycut::MemorySpace::host}, 2.0f, systems);
  c = {};
  c.radii = fine.data();
  try {
    query_engine.neighbours({.cutoffs = &c});
    ADD_FAILURE() << "per-pair cutoffs with query points were accepted";
  } catch (const raycut::Error& e) {
    EXPECT_NE(std::string(e.what()).find("not with query points"), std::string::npos) << e.what();
  }
}

}  // namespace
