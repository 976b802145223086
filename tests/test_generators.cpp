// The suites and test families: determinism, sizes, cutoffs, and the exact ties and special
// geometries each family exists for.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <limits>
#include <numbers>
#include <string>
#include <vector>

#include "raycut/error.hpp"
#include "raycut/predicate.hpp"
#include "raycut/tools/generators.hpp"

namespace raycut {
namespace {

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

float squared_distance_between(const PointCloud& cloud, std::size_t i, std::size_t j) {
  const float* p = &cloud.xyz[3 * i];
  const float* q = &cloud.xyz[3 * j];
  return squared_distance(q[0] - p[0], q[1] - p[1], q[2] - p[2]);
}

// Mean number of in-range neighbours per point, by brute force with the shared predicate.
double mean_neighbours(const PointCloud& cloud) {
  const float cutoff_squared = squared_cutoff(cloud.cutoff);
  std::size_t pairs = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    for (std::size_t j = 0; j < cloud.size(); ++j) {
      if (i != j && in_range(squared_distance_between(cloud, i, j), cutoff_squared)) ++pairs;
    }
  }
  return cloud.size() == 0 ? 0.0 : static_cast<double>(pairs) / static_cast<double>(cloud.size());
}

std::size_t expected_size(const std::string& family, std::size_t n) {
  if (family.starts_with("lattice-")) {
    if (n == 0) return 0;
    const auto side = std::max<long long>(1, std::llround(std::cbrt(static_cast<double>(n))));
    return static_cast<std::size_t>(side * side * side);
  }
  return n;
}

std::string error_message(const std::function<void()>& action, ErrorCode expected_code) {
  try {
    action();
  } catch (const Error& error) {
    EXPECT_EQ(error.code(), expected_code);
    return error.what();
  }
  ADD_FAILURE() << "no raycut::Error thrown";
  return "";
}

// ---- suites --------------------------------------------------------------------------------

TEST(GeneratorsUniformSuite, SizeCutoffAndName) {
  for (const auto& [beta, p] : {std::pair{2, 1}, {4, 8}, {8, 2}, {16, 1}}) {
    const PointCloud cloud = uniform_suite(beta, p);
    EXPECT_EQ(cloud.size(), static_cast<std::size_t>(p * beta * beta * beta));
    EXPECT_EQ(cloud.size(), suite_size(beta, p));
    EXPECT_EQ(cloud.cutoff, 1.0f / static_cast<float>(beta));
    EXPECT_EQ(cloud.name, "uniform beta=" + std::to_string(beta) + " p=" + std::to_string(p));
  }
}

TEST(GeneratorsUniformSuite, PointsLieInUnitCube) {
  const PointCloud cloud = uniform_suite(16, 8);
  for (float v : cloud.xyz) {
    ASSERT_GE(v, 0.0f);
    ASSERT_LT(v, 1.0f);
  }
}

TEST(GeneratorsUniformSuite, SameSeedSameBitsOtherSeedOtherBits) {
  EXPECT_TRUE(same_bits(uniform_suite(8, 4, 7).xyz, uniform_suite(8, 4, 7).xyz));
  EXPECT_FALSE(same_bits(uniform_suite(8, 4, 7).xyz, uniform_suite(8, 4, 8).xyz));
}

// Point i depends only on (seed, i): a small suite is a prefix of a large one, which also holds
// when the large one is generated on several threads.
TEST(GeneratorsUniformSuite, PointsDependOnlyOnSeedAndIndex) {
  const PointCloud small = uniform_suite(2, 1, 3);
  const PointCloud large = uniform_suite(32, 8, 3);  // 262,144 points: generated in parallel
  ASSERT_GT(large.size(), small.size());
  EXPECT_EQ(std::memcmp(small.xyz.data(), large.xyz.data(), small.xyz.size() * sizeof(float)), 0);
}

TEST(GeneratorsSurfaceSuite, SizeCutoffAndName) {
  for (const auto& [alpha, p] : {std::pair{2, 1}, {8, 1}, {8, 32}, {16, 4}}) {
    const PointCloud cloud = surface_suite(alpha, p);
    const std::size_t n = static_cast<std::size_t>(p) * alpha * alpha * alpha;
    EXPECT_EQ(cloud.size(), n);
    EXPECT_EQ(cloud.size(), suite_size(alpha, p));
    const double cos_cutoff = std::clamp(1.0 - 2.0 * 9.0 * p / static_cast<double>(n), -1.0, 1.0);
    EXPECT_EQ(cloud.cutoff, static_cast<float>(std::acos(cos_cutoff)));
    EXPECT_EQ(cloud.name, "surface alpha=" + std::to_string(alpha) + " p=" + std::to_string(p));
  }
  // 9p/N > 1 clamps to pi: every point is a neighbour.
  EXPECT_FLOAT_EQ(surface_suite(2, 1).cutoff, static_cast<float>(std::numbers::pi));
}

TEST(GeneratorsSurfaceSuite, PointsLieOnSphereAroundOneOneOne) {
  const PointCloud cloud = surface_suite(32, 2);
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    const double dx = cloud.xyz[3 * i] - 1.0, dy = cloud.xyz[3 * i + 1] - 1.0,
                 dz = cloud.xyz[3 * i + 2] - 1.0;
    ASSERT_NEAR(std::sqrt(dx * dx + dy * dy + dz * dz), 1.0, 1e-5) << "point " << i;
  }
}

TEST(GeneratorsSurfaceSuite, AboutNinePNeighbours) {
  const double mean = mean_neighbours(surface_suite(8, 2));
  EXPECT_GT(mean, 0.8 * 18);
  EXPECT_LT(mean, 1.3 * 18);
}

TEST(GeneratorsSurfaceSuite, DeterministicAndPrefixStable) {
  EXPECT_TRUE(same_bits(surface_suite(16, 2, 5).xyz, surface_suite(16, 2, 5).xyz));
  EXPECT_FALSE(same_bits(surface_suite(16, 2, 5).xyz, surface_suite(16, 2, 6).xyz));
  const PointCloud small = surface_suite(4, 1, 5);
  const PointCloud large = surface_suite(64, 1, 5);
  EXPECT_EQ(std::memcmp(small.xyz.data(), large.xyz.data(), small.xyz.size() * sizeof(float)), 0);
}

TEST(GeneratorsSuites, RejectNonPositiveParameters) {
  error_message([] { uniform_suite(0, 1); }, ErrorCode::invalid_argument);
  error_message([] { surface_suite(8, 0); }, ErrorCode::invalid_argument);
  error_message([] { suite_size(-2, 1); }, ErrorCode::invalid_argument);
  EXPECT_EQ(suite_size(256, 32), std::size_t{536870912});
}

// ---- families ------------------------------------------------------------------------------

TEST(GeneratorsFamilies, NamesInOrder) {
  const std::vector<std::string> expected = {"uniform",
                                             "sphere-surface",
                                             "lattice-k1",
                                             "lattice-k2",
                                             "lattice-k3",
                                             "lattice-k4",
                                             "lattice-shifted-k1",
                                             "lattice-shifted-k2",
                                             "lattice-shifted-k3",
                                             "lattice-shifted-k4",
                                             "coincident",
                                             "near-coincident",
                                             "axis-aligned",
                                             "diagonal",
                                             "gaussian-outlier",
                                             "offset-1e3",
                                             "offset-1e5",
                                             "large-cutoff",
                                             "tiny-scale",
                                             "huge-scale",
                                             "offset-1e7",
                                             "offset-1e15",
                                             "cauchy",
                                             "groups-far",
                                             "sheet-flat",
                                             "sheet-thin",
                                             "rod-1e6"};
  EXPECT_EQ(family_names(), expected);
}

TEST(GeneratorsFamilies, EverySizeIncludingZeroOneTwo) {
  for (const std::string& family : family_names()) {
    for (std::size_t n : {0, 1, 2, 3, 5, 64, 100, 1001}) {
      const PointCloud cloud = make_family(family, n, 1.0f, 42);
      EXPECT_EQ(cloud.size(), expected_size(family, n)) << family << " n=" << n;
      EXPECT_EQ(cloud.xyz.size() % 3, 0u);
      EXPECT_EQ(cloud.name, family);
      const float scale = family == "tiny-scale"   ? 0x1p-50f
                          : family == "huge-scale" ? 0x1p50f
                                                   : 1.0f;  // cutoff scaled with the cloud
      EXPECT_EQ(cloud.cutoff, scale);
      for (float v : cloud.xyz) ASSERT_TRUE(std::isfinite(v)) << family << " n=" << n;
    }
  }
}

TEST(GeneratorsFamilies, DeterministicPerSeed) {
  for (const std::string& family : family_names()) {
    const PointCloud a = make_family(family, 500, 0.75f, 9);
    EXPECT_TRUE(same_bits(a.xyz, make_family(family, 500, 0.75f, 9).xyz)) << family;
    if (!family.starts_with("lattice-")) {  // lattices take no randomness
      EXPECT_FALSE(same_bits(a.xyz, make_family(family, 500, 0.75f, 10).xyz)) << family;
    }
  }
}

// The families are meant to be searched with plenty of, but not too many, neighbours.
TEST(GeneratorsFamilies, NeighbourCountsAreModerate) {
  for (const char* family :
       {"uniform", "sphere-surface", "coincident", "near-coincident", "axis-aligned", "diagonal",
        "gaussian-outlier", "offset-1e3", "lattice-k2", "lattice-shifted-k2"}) {
    const double mean = mean_neighbours(make_family(family, 3000, 1.0f, 1));
    EXPECT_GE(mean, 8.0) << family;
    EXPECT_LE(mean, 45.0) << family;
  }
}

TEST(GeneratorsFamilies, RejectUnknownNameListingKnownOnes) {
  const std::string message =
      error_message([] { make_family("cubic", 10, 1.0f, 1); }, ErrorCode::invalid_argument);
  EXPECT_NE(message.find("'cubic'"), std::string::npos) << message;
  EXPECT_NE(message.find("uniform"), std::string::npos) << message;
  EXPECT_NE(message.find("large-cutoff"), std::string::npos) << message;
  for (const char* near_miss : {"lattice-k5", "lattice-k0", "lattice-k", "lattice-shifted-k12"}) {
    error_message([&] { make_family(near_miss, 10, 1.0f, 1); }, ErrorCode::invalid_argument);
  }
}

TEST(GeneratorsFamilies, RejectBadCutoff) {
  for (float cutoff : {0.0f, -1.0f, std::nanf(""), std::numeric_limits<float>::infinity()}) {
    error_message([&] { make_family("uniform", 10, cutoff, 1); }, ErrorCode::invalid_argument);
  }
}

// The scaled families scale the cutoff exactly (a power of two), and refuse to leave float.
TEST(GeneratorsFamilies, ScaledFamiliesAreExactCopies) {
  const PointCloud plain = make_family("uniform", 500, 0.75f, 3);
  const PointCloud tiny = make_family("tiny-scale", 500, 0.75f, 3);
  const PointCloud huge = make_family("huge-scale", 500, 0.75f, 3);
  ASSERT_EQ(tiny.size(), plain.size());
  ASSERT_EQ(huge.size(), plain.size());
  EXPECT_EQ(tiny.cutoff, std::ldexp(0.75f, -50));
  EXPECT_EQ(huge.cutoff, std::ldexp(0.75f, 50));
  for (std::size_t k = 0; k < plain.xyz.size(); ++k) {
    ASSERT_EQ(tiny.xyz[k], std::ldexp(plain.xyz[k], -50));
    ASSERT_EQ(huge.xyz[k], std::ldexp(plain.xyz[k], 50));
  }
  error_message([] { make_family("tiny-scale", 10, 1e-40f, 1); }, ErrorCode::invalid_argument);
  error_message([] { make_family("huge-scale", 10, 1e30f, 1); }, ErrorCode::invalid_argument);
}

// The far families: sheets exactly flat along their far axis, offsets rounded once, a rod of
// the announced shape, and a heavy tail.
TEST(GeneratorsFamilies, ExtremeShapes) {
  const PointCloud groups = make_family("groups-far", 4000, 1.0f, 2);
  ASSERT_EQ(groups.size(), 4000u);
  const std::size_t cube = 4000 - 3 * 1000;
  for (std::size_t g = 0; g < 3; ++g) {
    const float far = static_cast<float>(std::pow(10.0, 10.0 * (g + 1)));
    for (std::size_t i = cube + g * 1000; i < cube + (g + 1) * 1000; ++i)
      ASSERT_EQ(groups.xyz[3 * i + g], far) << "group " << g + 1 << " point " << i;
  }
  const PointCloud flat = make_family("sheet-flat", 1000, 1.0f, 2);
  for (std::size_t i = 0; i < flat.size(); ++i) ASSERT_EQ(flat.xyz[3 * i + 2], 0.0f);
  const PointCloud thin = make_family("sheet-thin", 1000, 1.0f, 2);
  for (std::size_t i = 0; i < thin.size(); ++i) {
    ASSERT_GE(thin.xyz[3 * i + 2], 0.0f);
    ASSERT_LE(thin.xyz[3 * i + 2], 1e-6f);
  }
  const PointCloud rod = make_family("rod-1e6", 1000, 2.0f, 2);
  float longest = 0;
  for (std::size_t i = 0; i < rod.size(); ++i) {
    ASSERT_LE(rod.xyz[3 * i], 2.0f);
    ASSERT_LE(rod.xyz[3 * i + 1], 2.0f);
    ASSERT_LE(rod.xyz[3 * i + 2], 2e6f);
    longest = std::max(longest, rod.xyz[3 * i + 2]);
  }
  EXPECT_GT(longest, 1e6f);
  for (const char* f : {"offset-1e7", "offset-1e15"}) {
    const float by = f == std::string("offset-1e7") ? 1e7f : 1e15f;
    for (float v : make_family(f, 1000, 1.0f, 2).xyz) ASSERT_GE(v, by) << f;
  }
  const PointCloud tail = make_family("cauchy", 4000, 1.0f, 2);
  float farthest = 0;
  for (float v : tail.xyz) farthest = std::max(farthest, std::fabs(v));
  EXPECT_GT(farthest, 1e3f);  // ~n cube sides away: a heavy tail
}

TEST(GeneratorsFamilies, LatticeSpacingCPutsPairsExactlyAtTheCutoff) {
  const PointCloud cloud = make_family("lattice-k1", 125, 1.0f, 1);
  ASSERT_EQ(cloud.size(), 125u);
  std::size_t at_cutoff = 0;
  for (std::size_t i = 0; i < cloud.size(); ++i) {
    for (std::size_t j = 0; j < cloud.size(); ++j) {
      if (i != j && squared_distance_between(cloud, i, j) == squared_cutoff(1.0f)) ++at_cutoff;
    }
  }
  EXPECT_EQ(at_cutoff, 2u * 3 * 4 * 5 * 5);  // ordered pairs of axis neighbours in a 5^3 block
  EXPECT_EQ(mean_neighbours(cloud), 0.0);    // at the cutoff is out of range
}

TEST(GeneratorsFamilies, LatticeK2InteriorPointHas26Neighbours) {
  const PointCloud cloud = make_family("lattice-k2", 7 * 7 * 7, 1.0f, 1);
  const std::size_t centre = (3 * 7 + 3) * 7 + 3;
  std::size_t neighbours = 0, at_cutoff = 0;
  for (std::size_t j = 0; j < cloud.size(); ++j) {
    const float d2 = squared_distance_between(cloud, centre, j);
    if (j != centre && in_range(d2, 1.0f)) ++neighbours;
    if (d2 == 1.0f) ++at_cutoff;
  }
  EXPECT_EQ(neighbours, 26u);
  EXPECT_EQ(at_cutoff, 6u);
}

TEST(GeneratorsFamilies, ShiftedLatticeIsOffsetByHalfASpacing) {
  const PointCloud plain = make_family("lattice-k4", 27, 1.0f, 1);
  const PointCloud shifted = make_family("lattice-shifted-k4", 27, 1.0f, 1);
  ASSERT_EQ(plain.size(), shifted.size());
  for (std::size_t i = 0; i < plain.xyz.size(); ++i) {
    EXPECT_EQ(shifted.xyz[i], plain.xyz[i] + 0.125f);
  }
}

TEST(GeneratorsFamilies, CoincidentHasExactCopies) {
  const PointCloud cloud = make_family("coincident", 1000, 1.0f, 3);
  std::size_t copies = 0;
  for (std::size_t i = 1; i < cloud.size(); ++i) {
    if (squared_distance_between(cloud, i - 1, i) == 0.0f) ++copies;
  }
  EXPECT_GT(copies, 500u);  // 1..6 copies per site: about 5/7 of the points repeat the previous
}

TEST(GeneratorsFamilies, NearCoincidentPairsAreCloseButDistinct) {
  const float cutoff = 2.0f;
  const PointCloud cloud = make_family("near-coincident", 2001, cutoff, 3);
  ASSERT_EQ(cloud.size(), 2001u);
  for (std::size_t i = 0; i + 1 < cloud.size(); i += 2) {
    const float* p = &cloud.xyz[3 * i];
    const float* q = &cloud.xyz[3 * i + 3];
    ASSERT_FALSE(p[0] == q[0] && p[1] == q[1] && p[2] == q[2]) << "pair " << i;
    const double dx = double(q[0]) - p[0], dy = double(q[1]) - p[1], dz = double(q[2]) - p[2];
    ASSERT_LE(std::sqrt(dx * dx + dy * dy + dz * dz), 1.01e-3 * cutoff) << "pair " << i;
  }
}

TEST(GeneratorsFamilies, AxisAlignedLinesShareTwoCoordinatesExactly) {
  const PointCloud cloud = make_family("axis-aligned", 24 * 4 * 6, 1.0f, 5);
  std::size_t equal_steps = 0, at_cutoff = 0;
  for (std::size_t line = 0; line < cloud.size() / 24; ++line) {
    const int axis = static_cast<int>(line / 4 % 3);
    const std::size_t first = 24 * line;
    const float step = cloud.xyz[3 * (first + 1) + axis] - cloud.xyz[3 * first + axis];
    for (std::size_t i = first + 1; i < first + 24; ++i) {
      for (int k = 0; k < 3; ++k) {
        if (k != axis) {
          ASSERT_EQ(cloud.xyz[3 * i + k], cloud.xyz[3 * first + k]);
        }
      }
      if (cloud.xyz[3 * i + axis] - cloud.xyz[3 * (i - 1) + axis] == step) ++equal_steps;
      if (i >= first + 2 && squared_distance_between(cloud, i - 2, i) == 1.0f) ++at_cutoff;
    }
  }
  EXPECT_EQ(equal_steps, cloud.size() / 24 * 23);  // every step of a line is the same float
  EXPECT_EQ(at_cutoff, 4u * 22);                   // the bundle of spacing C/2 (C = 1)
}

TEST(GeneratorsFamilies, DiagonalStepsHaveEqualComponents) {
  const PointCloud cloud = make_family("diagonal", 65 * 4, 0.3f, 5);
  std::size_t exact = 0;
  for (std::size_t star = 0; star < 4; ++star) {
    for (std::size_t d = 0; d < 4; ++d) {
      const std::size_t first = 65 * star + 1 + 16 * d;
      for (std::size_t i = first; i < first + 16; ++i) {
        for (std::size_t j = first; j < i; ++j) {
          const float dx = std::abs(cloud.xyz[3 * i] - cloud.xyz[3 * j]);
          const float dy = std::abs(cloud.xyz[3 * i + 1] - cloud.xyz[3 * j + 1]);
          const float dz = std::abs(cloud.xyz[3 * i + 2] - cloud.xyz[3 * j + 2]);
          ASSERT_GT(dx, 0.0f);
          ASSERT_EQ(dx, dy) << "star " << star << " diagonal " << d;
          ASSERT_EQ(dx, dz) << "star " << star << " diagonal " << d;
          ++exact;
        }
      }
    }
  }
  EXPECT_EQ(exact, 4u * 4 * (16 * 15 / 2));
}

TEST(GeneratorsFamilies, GaussianOutlierIsFarFromEverything) {
  const float cutoff = 0.5f;
  const PointCloud cloud = make_family("gaussian-outlier", 1000, cutoff, 2);
  const std::size_t outlier = cloud.size() - 1;
  for (std::size_t i = 0; i < outlier; ++i) {
    ASSERT_GT(squared_distance_between(cloud, i, outlier), (5e4f * cutoff) * (5e4f * cutoff));
  }
  const float* far = &cloud.xyz[3 * outlier];
  EXPECT_NEAR(std::sqrt(3.0) * far[0], 1e5 * cutoff, 1.0);
}

TEST(GeneratorsFamilies, OffsetsAreTheUniformCloudShifted) {
  const PointCloud uniform = make_family("uniform", 300, 1.0f, 4);
  const PointCloud shifted3 = make_family("offset-1e3", 300, 1.0f, 4);
  const PointCloud shifted5 = make_family("offset-1e5", 300, 1.0f, 4);
  for (std::size_t i = 0; i < uniform.xyz.size(); ++i) {
    ASSERT_EQ(shifted3.xyz[i], uniform.xyz[i] + 1e3f);
    ASSERT_EQ(shifted5.xyz[i], uniform.xyz[i] + 1e5f);
  }
}

TEST(GeneratorsFamilies, LargeCutoffPutsEveryPairInRange) {
  const PointCloud cloud = make_family("large-cutoff", 300, 1.0f, 4);
  EXPECT_EQ(mean_neighbours(cloud), 299.0);
}

}  // namespace
}  // namespace raycut
