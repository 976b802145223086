// The periodic oracle (tests/periodic_oracle.hpp) checked on its own: images counted by hand,
// against a naive search over a wide fixed range of images, invariance under unwrapping, the
// checker's verdicts, and ASE's neighbor_list("ijS") on three committed cases
// (tests/data/periodic_ase_*.txt, made by tests/data/make_periodic_ase.py).
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "periodic_oracle.hpp"

namespace raycut_test {
namespace {

struct TestBox {
  double cell[3][3] = {};
  bool pbc[3] = {true, true, true};
};

TestBox make_box(std::array<double, 9> rows, std::array<bool, 3> pbc = {true, true, true}) {
  TestBox box;
  for (int k = 0; k < 9; ++k) box.cell[k / 3][k % 3] = rows[k];
  for (int k = 0; k < 3; ++k) box.pbc[k] = pbc[k];
  return box;
}

// The oracle's own pairs as a list (i, j, S), in its orientation or all.
struct List {
  std::vector<std::uint32_t> i, j;
  std::vector<std::int32_t> s;
  void add(const PeriodicTriple& t) {
    i.push_back(static_cast<std::uint32_t>(t[0]));
    j.push_back(static_cast<std::uint32_t>(t[1]));
    for (int k = 2; k < 5; ++k) s.push_back(static_cast<std::int32_t>(t[k]));
  }
};

List list_of(const std::vector<PeriodicTriple>& triples, bool half) {
  List list;
  for (const PeriodicTriple& t : triples)
    if (!half || half_orientation(t)) list.add(t);
  return list;
}

std::size_t count_half(const std::vector<PeriodicTriple>& triples) {
  std::size_t n = 0;
  for (const PeriodicTriple& t : triples) n += half_orientation(t);
  return n;
}

void expect_ok(const PeriodicOracle& o, const List& list, bool half) {
  const PeriodicCheck check = check_periodic_pairs(o, list.i, list.j, list.s, half);
  EXPECT_TRUE(check.ok) << check.problems;
}

TEST(PeriodicOracle, TwoParticlesInACubeSmallerThanTheCutoff) {
  // L = 1, C = 1.2, particles at 0 and (0.5, 0, 0). By hand:
  //   (i, i, S): |S| < 1.2, S != 0: the 6 face neighbours, for each particle: 12.
  //   (0, 1, S): (0.5 + S0)^2 + S1^2 + S2^2 < 1.44: S0 in {-1, 0}, (S1, S2) in {0, (+-1, 0),
  //              (0, +-1)}: 10; and (1, 0, -S): 10.
  const PeriodicOracle o =
      make_periodic_oracle({0, 0, 0, 0.5f, 0, 0}, make_box({1, 0, 0, 0, 1, 0, 0, 0, 1}), 1.2);
  EXPECT_EQ(o.in.size(), 32u);
  EXPECT_EQ(o.band_pairs.size(), 0u);
  EXPECT_EQ(count_half(o.in), 16u);
  std::size_t self = 0;
  for (const PeriodicTriple& t : o.in) {
    if (t[0] != t[1]) continue;
    ++self;
    EXPECT_EQ(std::abs(t[2]) + std::abs(t[3]) + std::abs(t[4]), 1) << triple_text(t);
  }
  EXPECT_EQ(self, 12u);
  EXPECT_TRUE(std::binary_search(o.in.begin(), o.in.end(), PeriodicTriple{0, 1, -1, 1, 0}));
  EXPECT_FALSE(std::binary_search(o.in.begin(), o.in.end(), PeriodicTriple{0, 1, 1, 0, 0}));
  expect_ok(o, list_of(o.in, false), false);
  expect_ok(o, list_of(o.in, true), true);
}

TEST(PeriodicOracle, OneParticleInABoxOfWidthPoint3C) {
  // Self-images S != 0 with 0.3 |S| < 1: |S|^2 <= 11. Integer vectors by |S|^2 (r3(n)):
  // 1:6 2:12 3:8 4:6 5:24 6:24 7:0 8:12 9:30 10:24 11:24, in all 170 (|S|^2 = 12 is at 1.039 C).
  const PeriodicOracle o =
      make_periodic_oracle({0.1f, 0.2f, 0.3f}, make_box({0.3, 0, 0, 0, 0.3, 0, 0, 0, 0.3}), 1.0);
  EXPECT_EQ(o.in.size(), 170u);
  EXPECT_EQ(o.band_pairs.size(), 0u);
  EXPECT_EQ(count_half(o.in), 85u);
  for (const PeriodicTriple& t : o.in) EXPECT_EQ(t[0], t[1]);
  expect_ok(o, list_of(o.in, true), true);
}

TEST(PeriodicOracle, SlabHasNoImagesAlongItsOpenAxis) {
  // Square slab L = 1 in x, y, c zero (non-periodic), C = 1.2: each particle has 4 self-images
  // (S0^2 + S1^2 = 1); the second particle, 1.3 above the first, is no neighbour of it.
  const PeriodicOracle o = make_periodic_oracle(
      {0, 0, 0, 0, 0, 1.3f}, make_box({1, 0, 0, 0, 1, 0, 0, 0, 0}, {true, true, false}), 1.2);
  EXPECT_EQ(o.in.size(), 8u);
  for (const PeriodicTriple& t : o.in) {
    EXPECT_EQ(t[0], t[1]);
    EXPECT_EQ(t[4], 0);
  }
  // Closer than C along z: (0, 1, S) for S0^2 + S1^2 + 1.21 < 1.44: S = 0 only.
  const PeriodicOracle near = make_periodic_oracle(
      {0, 0, 0, 0, 0, 1.1f}, make_box({1, 0, 0, 0, 1, 0, 0, 0, 0}, {true, true, false}), 1.2);
  EXPECT_EQ(near.in.size(), 10u);
  EXPECT_TRUE(std::binary_search(near.in.begin(), near.in.end(), PeriodicTriple{0, 1, 0, 0, 0}));
}

// The oracle against a naive search of every S in [-K, K]^3 (0 on open axes), K fixed and wide.
TEST(PeriodicOracle, MatchesANaiveWideSearch) {
  const std::vector<std::pair<TestBox, double>> cases = {
      {make_box({1, 0, 0, 0.5, std::sqrt(3.0) / 2, 0, 0, 0, 1}), 1.5},           // 60 degrees
      {make_box({1.1, 0, 0, 0, 0, 0.9, 0.2, 1.0, 0}), 1.3},                      // left-handed
      {make_box({1.2, 0.1, -0.2, 0.4, 1.1, 0.1, -0.3, 0.2, 0.95}), 0.7},         // triclinic
      {make_box({1.1, 0, 0, 0.6, -0.9, 0, 0, 0, 0}, {true, true, false}), 1.4},  // slab
      {make_box({0, 0, 0, 0, 0, 0, 0.3, 0.4, 0.5}, {false, false, true}), 1.0},  // wire
  };
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1.5f, 2.5f);  // partly outside the cell
  for (const auto& [box, cutoff] : cases) {
    std::vector<float> xyz(3 * 9);
    for (float& v : xyz) v = u(rng);
    const PeriodicOracle o = make_periodic_oracle(xyz, box, cutoff);
    std::vector<PeriodicTriple> in, band;
    const int K = 12;
    int lim[3];
    for (int k = 0; k < 3; ++k) lim[k] = box.pbc[k] ? K : 0;
    for (std::int64_t i = 0; i < 9; ++i)
      for (std::int64_t j = 0; j < 9; ++j)
        for (std::int64_t a = -lim[0]; a <= lim[0]; ++a)
          for (std::int64_t b = -lim[1]; b <= lim[1]; ++b)
            for (std::int64_t c = -lim[2]; c <= lim[2]; ++c) {
              if (i == j && a == 0 && b == 0 && c == 0) continue;
              double r2 = 0;
              for (int x = 0; x < 3; ++x) {
                const double r = double(xyz[3 * j + x]) - double(xyz[3 * i + x]) +
                                 a * box.cell[0][x] + b * box.cell[1][x] + c * box.cell[2][x];
                r2 += r * r;
              }
              const double lo = cutoff * (1 - 1e-5), hi = cutoff * (1 + 1e-5);
              if (r2 < lo * lo)
                in.push_back({i, j, a, b, c});
              else if (r2 <= hi * hi)
                band.push_back({i, j, a, b, c});
            }
    EXPECT_EQ(o.in, in);  // both sorted
    EXPECT_EQ(o.band_pairs, band);
    EXPECT_GT(in.size(), 20u);
    for (const PeriodicTriple& t : in) {  // the search was wide enough
      for (int k = 2; k < 5; ++k) EXPECT_LT(std::abs(t[k]), K - 2);
    }
  }
}

// Unwrapping a particle by n cells changes its pairs' S by n_i - n_j, nothing else. Dyadic
// positions and cell, so the unwrapped floats are exact.
TEST(PeriodicOracle, UnwrappedPositionsShiftS) {
  const TestBox box = make_box({2, 0, 0, 0.5, 1.75, 0, -0.25, 0.5, 1.5});
  std::mt19937 rng(9);
  std::uniform_int_distribution<int> grid(0, 127), far(-1000, 1000);
  const std::size_t n = 12;
  std::vector<float> wrapped(3 * n), unwrapped(3 * n);
  std::vector<std::array<int, 3>> shift(n);
  for (std::size_t i = 0; i < n; ++i) {
    double f[3];
    for (double& v : f) v = grid(rng) / 128.0;
    shift[i] = {far(rng), far(rng), far(rng)};
    for (int c = 0; c < 3; ++c) {
      double x = 0, y = 0;
      for (int k = 0; k < 3; ++k) {
        x += f[k] * box.cell[k][c];
        y += (f[k] + shift[i][k]) * box.cell[k][c];
      }
      wrapped[3 * i + c] = static_cast<float>(x);
      unwrapped[3 * i + c] = static_cast<float>(y);
      ASSERT_EQ(double(wrapped[3 * i + c]), x);
      ASSERT_EQ(double(unwrapped[3 * i + c]), y);
    }
  }
  const PeriodicOracle a = make_periodic_oracle(wrapped, box, 2.3);
  const PeriodicOracle b = make_periodic_oracle(unwrapped, box, 2.3);
  ASSERT_EQ(a.in.size(), b.in.size());
  ASSERT_GT(a.in.size(), 100u);
  std::vector<PeriodicTriple> mapped;
  for (PeriodicTriple t : a.in) {  // x_j - x_i + S.cell = y_j - y_i + (S + n_i - n_j).cell
    for (int k = 0; k < 3; ++k) t[2 + k] += shift[t[0]][k] - shift[t[1]][k];
    mapped.push_back(t);
  }
  std::sort(mapped.begin(), mapped.end());
  EXPECT_EQ(mapped, b.in);
  expect_ok(b, list_of(b.in, true), true);
}

TEST(PeriodicOracle, CheckerCatchesEveryKindOfMistake) {
  const PeriodicOracle o =
      make_periodic_oracle({0, 0, 0, 0.5f, 0, 0}, make_box({1, 0, 0, 0, 1, 0, 0, 0, 1}), 1.2);
  const List full = list_of(o.in, false), half = list_of(o.in, true);
  expect_ok(o, full, false);
  expect_ok(o, half, true);
  auto check = [&](const List& l, bool h) { return check_periodic_pairs(o, l.i, l.j, l.s, h); };
  // Missing one.
  List l = full;
  l.i.pop_back(), l.j.pop_back(), l.s.resize(l.s.size() - 3);
  PeriodicCheck c = check(l, false);
  EXPECT_FALSE(c.ok);
  EXPECT_EQ(c.missing, 1u);
  EXPECT_NE(c.problems.find("missing"), std::string::npos) << c.problems;
  // A duplicate.
  l = full;
  l.add(o.in[3]);
  c = check(l, false);
  EXPECT_EQ(c.duplicates, 1u);
  EXPECT_FALSE(c.ok);
  // Out of range (the last one 7 cells away), a self pair.
  for (const PeriodicTriple& bad : {PeriodicTriple{0, 1, 1, 0, 0}, PeriodicTriple{1, 1, 0, 0, 0},
                                    PeriodicTriple{0, 1, 0, 0, 7}}) {
    l = full;
    l.add(bad);
    c = check(l, false);
    EXPECT_FALSE(c.ok) << triple_text(bad);
    EXPECT_EQ(c.out, 1u) << triple_text(bad);
  }
  // An index out of range; lists of different lengths.
  l = full;
  l.add({0, 2, 0, 0, 0});
  c = check(l, false);
  EXPECT_EQ(c.bad_index, 1u);
  l = full;
  l.s.pop_back();
  EXPECT_FALSE(check(l, false).ok);
  // The full list is not a half list, nor the half list a full one.
  c = check(full, true);
  EXPECT_FALSE(c.ok);
  EXPECT_EQ(c.wrong_orientation, 16u);
  c = check(half, false);
  EXPECT_EQ(c.missing, 16u);
  // A half list in the other orientation: each (i, j, S) replaced by (j, i, -S).
  List flipped;
  for (const PeriodicTriple& t : o.in)
    if (half_orientation(t)) flipped.add({t[1], t[0], -t[2], -t[3], -t[4]});
  c = check(flipped, true);
  EXPECT_EQ(c.wrong_orientation, 16u);
  EXPECT_EQ(c.missing, 16u);
  // An open axis: a shift along it is out.
  const PeriodicOracle slab = make_periodic_oracle(
      {0, 0, 0, 0.5f, 0, 0}, make_box({1, 0, 0, 0, 1, 0, 0, 0, 1}, {true, true, false}), 1.2);
  l = list_of(slab.in, false);
  EXPECT_TRUE(check_periodic_pairs(slab, l.i, l.j, l.s, false).ok);
  l.add({0, 1, 0, 0, 1});
  c = check_periodic_pairs(slab, l.i, l.j, l.s, false);
  EXPECT_NE(c.problems.find("non-periodic axis"), std::string::npos) << c.problems;
}

// The query variant: queries equal to the sources give the one-set pairs plus every (i, i, 0);
// distinct sets, a naive wide search as above.
TEST(PeriodicOracle, QueryVariantMatchesTheOneSetOracleAndANaiveSearch) {
  const TestBox box = make_box({1.1, 0, 0, 0.5, 0.9, 0, -0.2, 0.3, 0.8});
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1.0f, 2.0f);
  std::vector<float> points(3 * 8), queries(3 * 5);
  for (float& v : points) v = u(rng);
  for (float& v : queries) v = u(rng);
  const double cutoff = 1.3;
  const PeriodicOracle one = make_periodic_oracle(points, box, cutoff);
  const PeriodicOracle same = make_query_oracle(points, points, box, cutoff);
  std::vector<PeriodicTriple> want = one.in;
  for (std::int64_t i = 0; i < 8; ++i) want.push_back({i, i, 0, 0, 0});
  std::sort(want.begin(), want.end());
  EXPECT_EQ(same.in, want);
  expect_ok(same, list_of(same.in, false), false);

  const PeriodicOracle q = make_query_oracle(queries, points, box, cutoff);
  std::vector<PeriodicTriple> naive;
  const int K = 10;
  for (std::int64_t i = 0; i < 5; ++i)
    for (std::int64_t j = 0; j < 8; ++j)
      for (std::int64_t a = -K; a <= K; ++a)
        for (std::int64_t b = -K; b <= K; ++b)
          for (std::int64_t c = -K; c <= K; ++c) {
            double r2 = 0;
            for (int x = 0; x < 3; ++x) {
              const double r = double(points[3 * j + x]) - double(queries[3 * i + x]) +
                               a * box.cell[0][x] + b * box.cell[1][x] + c * box.cell[2][x];
              r2 += r * r;
            }
            const double lo = cutoff * (1 - 1e-5);
            if (r2 < lo * lo) naive.push_back({i, j, a, b, c});
          }
  EXPECT_EQ(q.in, naive);
  EXPECT_GT(naive.size(), 20u);
  // Indices are checked against their own set: 8 sources, 5 queries.
  List l = list_of(q.in, false);
  l.add({0, 8, 0, 0, 0});
  PeriodicCheck c = check_periodic_pairs(q, l.i, l.j, l.s, false);
  EXPECT_EQ(c.bad_index, 1u);
  l = list_of(q.in, false);
  l.add({5, 0, 0, 0, 0});
  c = check_periodic_pairs(q, l.i, l.j, l.s, false);
  EXPECT_EQ(c.bad_index, 1u);
}

TEST(PeriodicOracle, BandPairsAtMostOnce) {
  // d = 1 = C exactly (a power of two, exact in float): in the band, either answer accepted.
  const PeriodicOracle o =
      make_periodic_oracle({0, 0, 0, 1, 0, 0}, make_box({4, 0, 0, 0, 4, 0, 0, 0, 4}), 1.0);
  EXPECT_TRUE(o.in.empty());
  ASSERT_EQ(o.band_pairs.size(), 2u);
  List none;
  EXPECT_TRUE(check_periodic_pairs(o, none.i, none.j, none.s, false).ok);
  List once = list_of(o.band_pairs, false);
  PeriodicCheck c = check_periodic_pairs(o, once.i, once.j, once.s, false);
  EXPECT_TRUE(c.ok) << c.problems;
  EXPECT_EQ(c.listed_band, 2u);
  once.add(o.band_pairs[0]);
  EXPECT_FALSE(check_periodic_pairs(o, once.i, once.j, once.s, false).ok);
}

// ASE's neighbor_list("ijS") (ASE 3.29.0) on the committed cases.
struct AseCase {
  TestBox box;
  double cutoff = 0;
  std::vector<float> xyz;
  List pairs;
};

AseCase read_ase_case(const std::string& name) {
  const std::filesystem::path file =
      std::filesystem::path(RAYCUT_TEST_DATA) / ("periodic_ase_" + name + ".txt");
  std::ifstream in(file);
  EXPECT_TRUE(in) << "cannot open " << file;
  AseCase c;
  std::string word;
  while (in >> word) {
    if (word == "#") {
      std::getline(in, word);
    } else if (word == "cutoff") {
      in >> c.cutoff;
    } else if (word == "pbc") {
      for (bool& p : c.box.pbc) in >> p;
    } else if (word == "cell") {
      for (auto& row : c.box.cell)
        for (double& v : row) in >> v;
    } else if (word == "positions") {
      std::size_t n = 0;
      in >> n;
      for (std::size_t k = 0; k < 3 * n; ++k) {
        double v = 0;
        in >> v;
        c.xyz.push_back(static_cast<float>(v));
        EXPECT_EQ(double(c.xyz.back()), v) << "not a float value: " << v;
      }
    } else if (word == "pairs") {
      std::size_t m = 0;
      in >> m;
      for (std::size_t k = 0; k < m; ++k) {
        std::int64_t i, j, s0, s1, s2;
        in >> i >> j >> s0 >> s1 >> s2;
        c.pairs.add({i, j, s0, s1, s2});
      }
    } else {
      ADD_FAILURE() << file << ": unexpected " << word;
      break;
    }
  }
  EXPECT_FALSE(in.bad());
  return c;
}

class PeriodicOracleAse : public ::testing::TestWithParam<std::string> {};

TEST_P(PeriodicOracleAse, ReproducesAseExactly) {
  const AseCase c = read_ase_case(GetParam());
  ASSERT_GT(c.pairs.i.size(), 50u);
  const PeriodicOracle o = make_periodic_oracle(c.xyz, c.box, c.cutoff);
  const PeriodicCheck full = check_periodic_pairs(o, c.pairs.i, c.pairs.j, c.pairs.s, false);
  EXPECT_TRUE(full.ok) << full.problems;
  // No pair near the cutoff in these cases, so the sets are equal.
  EXPECT_TRUE(o.band_pairs.empty());
  EXPECT_EQ(c.pairs.i.size(), o.in.size());
  // ASE's full list, cut to the half orientation, is the oracle's half list.
  List half;
  for (std::size_t p = 0; p < c.pairs.i.size(); ++p) {
    const PeriodicTriple t{c.pairs.i[p], c.pairs.j[p], c.pairs.s[3 * p], c.pairs.s[3 * p + 1],
                           c.pairs.s[3 * p + 2]};
    if (half_orientation(t)) half.add(t);
  }
  EXPECT_EQ(2 * half.i.size(), c.pairs.i.size());
  const PeriodicCheck h = check_periodic_pairs(o, half.i, half.j, half.s, true);
  EXPECT_TRUE(h.ok) << h.problems;
}

INSTANTIATE_TEST_SUITE_P(Cases, PeriodicOracleAse,
                         ::testing::Values("cubic_small", "triclinic_unwrapped", "slab_left"));

}  // namespace
}  // namespace raycut_test
