// Periodic pairs exact at every box size: a fuzz test against the double-precision image oracle
// (tests/periodic_oracle.hpp, which shares no code with src/), over random boxes with L / C from 1
// to 10^6, skewed triclinic cells, partial pbc, positions unwrapped by up to 10^3 boxes,
// duplicates, points on faces and corners, and pairs placed within 1e-7 to 1e-2 of the cutoff
// across the box's faces. Every listed (i, j, S) must be the oracle's answer outside a band of
// 1e-6 relative around the cutoff; the full list must be symmetric ((i, j, S) listed iff
// (j, i, -S) is, band pairs included), the half list exactly its half-orientation part, and the
// count kernel (a functor that reads neither j nor S: the open traversal) must count each full
// row. Every method that takes boxes, CPU and CUDA; methods not available here (no GPU) are
// skipped with the reason.
//
// A fixed list of seeds runs every time, plus one fresh seed, printed on failure
// (RAYCUT_FUZZ_SEED=<seed> replays one case).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <random>
#include <set>
#include <string>
#include <vector>

#include "method_availability.hpp"
#include "periodic_oracle.hpp"
#include "raycut/box.hpp"
#include "raycut/engine.hpp"

namespace {

// The methods that take boxes.
const std::vector<std::string> exact_methods = {"brute-force", "cell-list", "brute-force-gpu",
                                                "grid"};

using raycut_test::unavailable;

class PeriodicExact : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    const std::string why = unavailable(GetParam());
    if (!why.empty()) GTEST_SKIP() << GetParam() << ": " << why;
  }
};

struct FuzzCase {
  std::uint64_t seed = 0;
  double cutoff = 1;
  raycut::Box box;
  std::vector<float> xyz;
  std::vector<double> xyz64;  // the same points before their rounding to float
  std::string description;
};

// A random case: the cell, then particles in pairs and clusters placed relative to each other
// (random points in a box 10^6 cutoffs wide would have no pairs at all).
FuzzCase make_case(std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  FuzzCase c;
  c.seed = seed;
  c.cutoff = std::ldexp(1.0 + unit(rng), static_cast<int>(unit(rng) * 8) - 4);  // 1/16 .. 32
  const double ratio = std::pow(10.0, 6 * unit(rng));                           // L / C
  const double length = ratio * c.cutoff;
  const int kind = static_cast<int>(unit(rng) * 3);  // orthorhombic, skewed, strongly skewed
  for (int k = 0; k < 3; ++k) {
    const double side = length * (0.5 + unit(rng));
    c.box.cell[k][k] = side;
    for (int m = 0; m < k && kind > 0; ++m)
      c.box.cell[k][m] = (kind == 1 ? 0.3 : 0.9) * side * (2 * unit(rng) - 1);
    c.box.pbc[k] = unit(rng) < 0.8;
  }
  const auto at = [&](const std::array<double, 3>& f) {  // fractional -> Cartesian
    std::array<double, 3> x{};
    for (int k = 0; k < 3; ++k)
      for (int d = 0; d < 3; ++d) x[d] += f[k] * c.box.cell[k][d];
    return x;
  };
  std::vector<std::array<double, 3>> points;
  const int groups = 4 + static_cast<int>(unit(rng) * 8);
  for (int g = 0; g < groups; ++g) {
    // A base on a face, an edge, a corner or anywhere in the cell.
    std::array<double, 3> f{};
    for (int k = 0; k < 3; ++k) {
      const double u = unit(rng);
      f[k] = u < 0.2 ? 0.0 : u < 0.35 ? 1.0 : u < 0.45 ? 1.0 - 1e-9 : unit(rng);
    }
    const std::array<double, 3> base = at(f);
    points.push_back(base);
    // Partners at a distance near the cutoff: in, out, and within 1e-7 .. 1e-2 of it.
    const int partners = 1 + static_cast<int>(unit(rng) * 5);
    for (int p = 0; p < partners; ++p) {
      std::array<double, 3> dir{};
      double norm = 0;
      for (double& v : dir) {
        v = 2 * unit(rng) - 1;
        norm += v * v;
      }
      norm = std::sqrt(norm);
      const double offset = (unit(rng) < 0.5 ? -1 : 1) * std::pow(10.0, -7 + 5 * unit(rng));
      const double d = unit(rng) < 0.2 ? c.cutoff * unit(rng) : c.cutoff * (1 + offset);
      std::array<double, 3> x{};
      for (int a = 0; a < 3; ++a) x[a] = base[a] + d * dir[a] / norm;
      points.push_back(x);
    }
    if (unit(rng) < 0.2) points.push_back(base);  // a duplicate
  }
  // Unwrap: each particle moved by whole cells, up to 10^3 boxes away.
  const bool unwrapped = unit(rng) < 0.5;
  for (auto& x : points) {
    if (!unwrapped) break;
    for (int k = 0; k < 3; ++k) {
      if (!c.box.pbc[k]) continue;
      const double n = std::round((2 * unit(rng) - 1) * (unit(rng) < 0.3 ? 1000 : 2));
      for (int d = 0; d < 3; ++d) x[d] += n * c.box.cell[k][d];
    }
  }
  for (const auto& x : points)
    for (double v : x) {
      c.xyz.push_back(static_cast<float>(v));
      c.xyz64.push_back(v);
    }
  c.description = "seed " + std::to_string(seed) + ": L/C " + std::to_string(ratio) + ", cell " +
                  (kind == 0   ? "orthorhombic"
                   : kind == 1 ? "skewed"
                               : "strongly skewed") +
                  ", pbc " + std::to_string(c.box.pbc[0]) + std::to_string(c.box.pbc[1]) +
                  std::to_string(c.box.pbc[2]) + (unwrapped ? ", unwrapped" : "") + ", N " +
                  std::to_string(points.size());
  return c;
}

// Runs one case on one method, from the float positions or the float64 ones (then the oracle
// takes those); returns the failures (empty when it passes).
std::string run_case(const FuzzCase& c, const std::string& method, bool float64) {
  raycut::Engine engine(method);
  try {
    if (float64)
      engine.build(raycut::Float64Positions{c.xyz64.data(), c.xyz64.size() / 3},
                   static_cast<float>(c.cutoff), raycut::Systems::periodic(c.box));
    else
      engine.build({c.xyz.data(), c.xyz.size() / 3, raycut::MemorySpace::host},
                   static_cast<float>(c.cutoff), c.box);
  } catch (const raycut::Error& e) {
    return std::string("build refused: ") + e.what();
  }
  const raycut::NeighbourList full = engine.neighbours({.shifts = true});
  const raycut::NeighbourList half = engine.neighbours({.half = true, .shifts = true});
  const double cutoff = static_cast<float>(c.cutoff);
  const raycut_test::PeriodicOracle oracle =
      float64 ? raycut_test::make_periodic_oracle(c.xyz64, c.box, cutoff, 1e-6)
              : raycut_test::make_periodic_oracle(c.xyz, c.box, cutoff, 1e-6);
  std::string failures = raycut_test::check_full_and_half(oracle, full, half);
  // The count kernel reads neither j nor S: it runs the open traversal, with the same decision.
  const std::vector<std::uint32_t> counts = engine.compute(raycut::Kernel::count).count;
  for (std::size_t i = 0; i + 1 < full.offsets.size(); ++i)
    if (counts.at(i) != full.offsets[i + 1] - full.offsets[i])
      failures += "count kernel: row " + std::to_string(i) + " counts " +
                  std::to_string(counts[i]) + ", the full list holds " +
                  std::to_string(full.offsets[i + 1] - full.offsets[i]) + "\n";
  return failures;
}

void run_seed(const std::string& method, std::uint64_t seed) {
  const FuzzCase c = make_case(seed);
  for (const bool float64 : {false, true}) {
    const std::string failures = run_case(c, method, float64);
    EXPECT_TRUE(failures.empty()) << method << (float64 ? ", float64 positions" : "") << ", "
                                  << c.description << " (replay with RAYCUT_FUZZ_SEED=" << seed
                                  << "):\n"
                                  << failures.substr(0, 2000);
  }
}

TEST_P(PeriodicExact, FuzzFixedSeeds) {
  if (const char* replay = std::getenv("RAYCUT_FUZZ_SEED")) {
    run_seed(GetParam(), std::strtoull(replay, nullptr, 10));
    return;
  }
  for (std::uint64_t seed = 1; seed <= 300; ++seed) {
    run_seed(GetParam(), seed);
    if (HasFailure()) return;  // the first failing seed says enough
  }
}

// Batches: three random systems in one build, each in its own box (and its own frame), each
// system's rows checked against its own oracle, and no pair across systems.
TEST_P(PeriodicExact, FuzzBatches) {
  for (std::uint64_t seed = 1000; seed < 1060; ++seed) {
    const FuzzCase cases[3] = {make_case(seed), make_case(seed + 7919), make_case(seed + 104729)};
    std::vector<float> xyz;
    raycut::Systems systems;
    systems.offsets = {0};
    // One cutoff for the batch: the smallest, so every system's own cutoff-scaled layout stays
    // near its pairs (the oracle takes the same cutoff).
    double cutoff = cases[0].cutoff;
    for (const FuzzCase& c : cases) cutoff = std::min(cutoff, c.cutoff);
    for (const FuzzCase& c : cases) {
      xyz.insert(xyz.end(), c.xyz.begin(), c.xyz.end());
      systems.offsets.push_back(xyz.size() / 3);
      systems.boxes.push_back(c.box);
    }
    const auto c32 = static_cast<float>(cutoff);
    const std::string& method = GetParam();
    raycut::Engine engine(method);
    engine.build({xyz.data(), xyz.size() / 3, raycut::MemorySpace::host}, c32, systems);
    const raycut::NeighbourList list = engine.neighbours({.shifts = true});
    for (std::size_t s = 0; s < 3; ++s) {
      const std::uint64_t first = systems.offsets[s], last = systems.offsets[s + 1];
      std::vector<std::uint32_t> i, j;
      std::vector<std::int32_t> shifts;
      for (std::uint64_t r = first; r < last; ++r)
        for (std::uint64_t p = list.offsets[r]; p < list.offsets[r + 1]; ++p) {
          ASSERT_TRUE(list.indices[p] >= first && list.indices[p] < last)
              << method << ", seed " << seed << ": a pair across systems";
          i.push_back(static_cast<std::uint32_t>(r - first));
          j.push_back(static_cast<std::uint32_t>(list.indices[p] - first));
          shifts.insert(shifts.end(), &list.shifts[3 * p], &list.shifts[3 * p + 3]);
        }
      const raycut_test::PeriodicOracle oracle = raycut_test::make_periodic_oracle(
          cases[s].xyz, cases[s].box, static_cast<double>(c32), 1e-6);
      const raycut_test::PeriodicCheck check =
          raycut_test::check_periodic_pairs(oracle, i, j, shifts, false);
      ASSERT_TRUE(check.ok) << method << ", batch of seed " << seed << ", system " << s << " ("
                            << cases[s].description << "):\n"
                            << check.problems;
    }
  }
}

TEST_P(PeriodicExact, FuzzFreshSeed) {
  const std::uint64_t seed = std::random_device{}() | (std::uint64_t{std::random_device{}()} << 32);
  SCOPED_TRACE("fresh seed " + std::to_string(seed));
  run_seed(GetParam(), seed);
}

// The case the float decision got wrong: a pair across the face of a box 10^4 cutoffs wide, at
// 3.8e-4 inside the cutoff. The image of particle 0, 0.3004 + 10^4, rounds to 10000.30078125 in
// float, exactly 1 from particle 1: the float predicate listed the pair in row 0 (no image
// rounded there) and not in row 1.
TEST_P(PeriodicExact, PairAcrossTheFaceOfAHugeBoxAtTheCutoff) {
  const std::string& method = GetParam();
  raycut::Box box;
  const double length = 1e4;
  for (int k = 0; k < 3; ++k) {
    box.cell[k][k] = length;
    box.pbc[k] = true;
  }
  const float a = 0.3004f, b = 9999.30078125f;
  const double d = static_cast<double>(a) + length - static_cast<double>(b);
  const std::vector<float> xyz = {a, 5000, 5000, b, 5000, 5000};
  raycut::Engine engine(method);
  engine.build({xyz.data(), 2, raycut::MemorySpace::host}, 1.0f, box);
  const raycut::NeighbourList list = engine.neighbours({.vectors = true, .shifts = true});
  ASSERT_LT(d, 1.0);
  ASSERT_EQ(list.indices.size(), 2u) << method << " at d = " << d;
  ASSERT_EQ(list.offsets[1], 1u) << method;
  // r in double, rounded once: not off by the box's float rounding.
  EXPECT_EQ(list.vectors[0], static_cast<float>(-d)) << method;
  EXPECT_EQ(list.vectors[3], static_cast<float>(d)) << method;
  EXPECT_EQ(list.shifts[0], -1) << method;
  EXPECT_EQ(list.shifts[3], 1) << method;
}

// float64 positions in an open cloud far from the origin: the two points round to floats 1.0
// apart (spacing 0.0625 at 1e6) while they are 1 - 1e-9 apart, so the float search alone says
// "no pair". The float64 build lists the pair, with r from the doubles; update() keeps that.
TEST_P(PeriodicExact, Float64OpenCloudFarFromTheOrigin) {
  const std::vector<double> xyz = {1e6 + 0.01, 0, 0, 1e6 + 1.01 - 1e-9, 0, 0};
  const std::string& method = GetParam();
  raycut::Engine engine(method);
  engine.build(raycut::Float64Positions{xyz.data(), 2}, 1.0f);
  raycut::NeighbourList list = engine.neighbours({.vectors = true});
  ASSERT_EQ(list.indices.size(), 2u) << method;
  EXPECT_EQ(list.vectors[0], static_cast<float>(xyz[3] - xyz[0])) << method;
  std::vector<double> moved = xyz;
  moved[3] += 2e-9;  // now 1 + 1e-9 apart: out
  engine.update(raycut::Float64Positions{moved.data(), 2});
  EXPECT_EQ(engine.neighbours().indices.size(), 0u) << method;
  // The same positions as float32: their rounding decides (1.0 apart: no pair).
  const std::vector<float> rounded(xyz.begin(), xyz.end());
  engine.build({rounded.data(), 2, raycut::MemorySpace::host}, 1.0f);
  EXPECT_EQ(engine.neighbours().indices.size(), 0u) << method;
}

TEST_P(PeriodicExact, Float64RefusesWhatFloatCannotHold) {
  raycut::Engine engine(GetParam());
  const std::vector<double> huge = {0, 0, 0, 1e39, 0, 0};
  try {
    engine.build(raycut::Float64Positions{huge.data(), 2}, 1.0f);
    FAIL() << "1e39 accepted";
  } catch (const raycut::Error& e) {
    EXPECT_NE(std::string(e.what()).find("particle index 1"), std::string::npos) << e.what();
  }
  const std::vector<double> nan = {0, 0, std::nan(""), 0, 0, 0};
  EXPECT_THROW(engine.build(raycut::Float64Positions{nan.data(), 2}, 1.0f), raycut::Error);
}

INSTANTIATE_TEST_SUITE_P(Methods, PeriodicExact, ::testing::ValuesIn(exact_methods),
                         [](const auto& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

}  // namespace
