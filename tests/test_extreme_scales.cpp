// Every method (CPU and, where available, GPU) on the extreme-scale families and at the edges of
// the supported cutoff range, against the double-precision oracle of tests/oracle.hpp, which does
// not share raycut's predicate (docs/limits.md). Just outside the range, and on the
// inputs that used to give silently wrong answers, build() must refuse with a clear
// Error naming the supported range.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <string>
#include <tuple>
#include <vector>

#include "oracle.hpp"
#include "raycut/engine.hpp"
#include "raycut/tools/generators.hpp"

namespace {

using raycut::Engine;
using raycut::Kernel;
using raycut::MemorySpace;
using raycut::PointCloud;

struct Case {
  std::string family;  // a generator family, or "pair-2e19" (two points 2e19 apart)
  std::size_t n;
  float cutoff;  // passed to make_family; the cloud's own cutoff may be rescaled
  bool refused;  // the cloud's cutoff is outside [2^-60, 2^60]: build() must refuse
};

void PrintTo(const Case& c, std::ostream* os) {
  *os << c.family << " n=" << c.n << " cutoff=" << c.cutoff << (c.refused ? " (refused)" : "");
}

PointCloud cloud_of(const Case& c) {
  if (c.family == "pair-2e19")
    return {"pair-2e19", {0, 0, 0, 2e19f, 0, 0}, c.cutoff, raycut::Box::open()};
  return raycut::make_family(c.family, c.n, c.cutoff, /*seed=*/17 + c.n);
}

struct Reference {
  PointCloud cloud;
  raycut_test::DoubleOracle oracle;
};

const Reference& reference(const Case& c) {
  static std::map<std::string, Reference> cache;
  const std::string key = c.family + '/' + std::to_string(c.n) + '/' + std::to_string(c.cutoff);
  auto [it, inserted] = cache.try_emplace(key);
  if (inserted) {
    it->second.cloud = cloud_of(c);
    if (!c.refused)
      it->second.oracle = raycut_test::make_oracle(it->second.cloud.xyz, it->second.cloud.cutoff);
  }
  return it->second;
}

bool is_cpu(const std::string& method) {
  return method == "brute-force" || method == "cell-list";
}

class ExtremeScales : public ::testing::TestWithParam<std::tuple<std::string, Case>> {};

TEST_P(ExtremeScales, MatchesTheDoubleOracle) {
  const auto& [method, c] = GetParam();
  for (const auto& m : raycut::list_methods())
    if (m.name == method && !m.available) GTEST_SKIP() << method << ": " << m.why_unavailable;
  // O(N^2) on the CPU: the brute-force method only up to 10,000 particles here.
  if (method == "brute-force" && c.n > 10000) GTEST_SKIP() << "brute force above 10,000 on CPU";

  const Reference& ref = reference(c);
  const PointCloud& cloud = ref.cloud;
  const std::size_t n = cloud.size();
  Engine engine(method);

  if (c.refused) {
    try {
      engine.build({cloud.xyz.data(), n, MemorySpace::host}, cloud.cutoff);
      FAIL() << "cutoff " << cloud.cutoff << " accepted; expected a refusal";
    } catch (const raycut::Error& e) {
      EXPECT_EQ(e.code(), raycut::ErrorCode::invalid_argument) << e.what();
      EXPECT_NE(std::string(e.what()).find("supported range"), std::string::npos) << e.what();
    }
    return;
  }

  raycut::NeighbourList list;
  std::vector<std::uint32_t> count;
  try {
    engine.build({cloud.xyz.data(), n, MemorySpace::host}, cloud.cutoff);
    list = engine.neighbours();
    count = engine.compute(Kernel::count).count;
  } catch (const raycut::Error& e) {
    // A method may refuse an input it cannot resolve (an OptiX scene, a dense grid out of
    // memory), with a message and not as a bug. The CPU methods handle every input in range.
    ASSERT_FALSE(is_cpu(method)) << "the CPU methods must not refuse: " << e.what();
    ASSERT_NE(e.code(), raycut::ErrorCode::internal) << e.what();
    ASSERT_FALSE(std::string(e.what()).empty());
    RecordProperty("refused", e.what());
    GTEST_SKIP() << method << " refused (" << raycut::to_string(e.code()) << "): " << e.what();
  }

  const auto listed = raycut_test::check_list(list, ref.oracle);
  EXPECT_TRUE(listed.ok) << listed.bad_targets << " of " << n << " targets wrong; first "
                         << listed.first_problem;
  const auto counted = raycut_test::check_counts(count, ref.oracle);
  EXPECT_TRUE(counted.ok) << counted.bad_targets << " of " << n << " counts wrong; first "
                          << counted.first_problem;
  // The count kernel and the list decide each pair with the same predicate.
  if (listed.ok && count.size() == n) {
    for (std::size_t i = 0; i < n; ++i)
      ASSERT_EQ(count[i], list.offsets[i + 1] - list.offsets[i]) << "target " << i;
  }
  RecordProperty("oracle_in_pairs", std::to_string(ref.oracle.in_pairs));
  RecordProperty("oracle_band_pairs", std::to_string(ref.oracle.band_pairs));
}

const std::vector<std::string> new_families = {"tiny-scale",  "huge-scale", "offset-1e7",
                                               "offset-1e15", "cauchy",     "groups-far",
                                               "sheet-flat",  "sheet-thin", "rod-1e6"};

std::vector<Case> cases() {
  std::vector<Case> out;
  for (const auto& f : new_families) {
    for (std::size_t n : {0, 1, 2, 1000, 5000}) out.push_back({f, n, 1.0f, false});
    out.push_back({f, 3000, 0.37f, false});
  }
  // Above the oracle's brute-force limit: its cell hash, and the methods' large-N paths.
  for (const char* f : {"cauchy", "groups-far", "offset-1e15", "sheet-flat"})
    out.push_back({f, 30000, 1.0f, false});
  // The edges of [2^-60, 2^60]: the scaled families' cutoff is C 2^-50 / C 2^50.
  for (std::size_t n : {1000, 5000}) {
    out.push_back({"tiny-scale", n, 0x1p-10f, false});
    out.push_back({"huge-scale", n, 0x1p10f, false});
  }
  // Old families at the edges: coincident points, pairs 1e-7 C apart (their squares underflow
  // float, harmlessly), exact ties at the cutoff, and far pairs whose squares overflow to inf.
  for (const char* f : {"coincident", "near-coincident", "lattice-k2", "uniform"}) {
    out.push_back({f, 2000, 0x1p-60f, false});
    out.push_back({f, 2000, 0x1p60f, false});
  }
  // Just outside the range, and the inputs that used to be silently wrong: refused.
  out.push_back({"tiny-scale", 1000, 0x1p-11f, true});
  out.push_back({"huge-scale", 1000, 0x1p11f, true});
  out.push_back({"coincident", 1000, 1e-30f, true});
  out.push_back({"uniform", 1000, 1e30f, true});
  out.push_back({"pair-2e19", 2, 1e20f, true});
  return out;
}

std::vector<std::string> all_methods() {
  std::vector<std::string> names;
  for (const auto& m : raycut::list_methods()) names.push_back(m.name);
  return names;
}

std::string test_name(const ::testing::TestParamInfo<ExtremeScales::ParamType>& info) {
  const auto& [method, c] = info.param;
  char text[32];
  std::snprintf(text, sizeof text, "%g", c.cutoff);
  std::string cutoff = text;
  for (char& ch : cutoff) {
    if (ch == '-') ch = 'm';  // 1e-30 and 1e+30 must not give the same name
    if (ch == '+') ch = 'p';
  }
  std::string name = method + "_" + c.family + "_n" + std::to_string(c.n) + "_c" + cutoff;
  for (char& ch : name)
    if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
  return name;
}

INSTANTIATE_TEST_SUITE_P(Methods, ExtremeScales,
                         ::testing::Combine(::testing::ValuesIn(all_methods()),
                                            ::testing::ValuesIn(cases())),
                         test_name);

// The oracle's two counting paths agree (brute force and its own cell hash), and its in-set is
// what a plain double loop says, on every new family.
TEST(DoubleOracle, CellHashAgreesWithBruteForce) {
  for (const auto& f : new_families) {
    const PointCloud cloud = raycut::make_family(f, 3000, 1.0f, 5);
    const auto brute = raycut_test::make_oracle(cloud.xyz, cloud.cutoff, 1e-5, 1u << 30);
    const auto cells = raycut_test::make_oracle(cloud.xyz, cloud.cutoff, 1e-5, 0);
    EXPECT_EQ(brute.in, cells.in) << f;
    EXPECT_EQ(brute.band_count, cells.band_count) << f;
    EXPECT_GT(brute.in_pairs + (f == "rod-1e6" ? 1 : 0), 0u) << f;
  }
}

// The oracle is not the predicate: it sees the pairs that a plain float predicate loses.
TEST(DoubleOracle, SeesWhatTheFloatPredicateLost) {
  const std::vector<float> coincident = {1e-20f, 0, 0, 1e-20f, 0, 0};
  const auto o = raycut_test::make_oracle(coincident, 1e-30f);
  EXPECT_EQ(o.in, (std::vector<std::uint32_t>{1, 1}));
  const std::vector<float> far = {0, 0, 0, 2e19f, 0, 0};
  EXPECT_EQ(raycut_test::make_oracle(far, 1e20f).in_pairs, 2u);
  // A list with an extra out pair, a duplicate or a missing pair is caught.
  const std::vector<float> three = {0, 0, 0, 0.5f, 0, 0, 3, 0, 0};
  const auto o3 = raycut_test::make_oracle(three, 1.0f);
  const auto csr = [](std::vector<std::uint64_t> offsets, std::vector<std::uint32_t> indices) {
    raycut::NeighbourList list;
    list.offsets = std::move(offsets);
    list.indices = std::move(indices);
    return list;
  };
  raycut::NeighbourList good = csr({0, 1, 2, 2}, {1, 0});
  EXPECT_TRUE(raycut_test::check_list(good, o3).ok);
  raycut::NeighbourList extra = csr({0, 2, 3, 3}, {1, 2, 0});
  EXPECT_FALSE(raycut_test::check_list(extra, o3).ok);
  raycut::NeighbourList twice = csr({0, 2, 3, 3}, {1, 1, 0});
  EXPECT_FALSE(raycut_test::check_list(twice, o3).ok);
  raycut::NeighbourList missing = csr({0, 1, 1, 1}, {1});
  EXPECT_FALSE(raycut_test::check_list(missing, o3).ok);
  // A pair within the band may be listed or not.
  const std::vector<float> tie = {0, 0, 0, 1, 0, 0};
  const auto ot = raycut_test::make_oracle(tie, 1.0f);
  EXPECT_TRUE(raycut_test::check_list(csr({0, 0, 0}, {}), ot).ok);
  EXPECT_TRUE(raycut_test::check_list(csr({0, 1, 2}, {1, 0}), ot).ok);
  EXPECT_TRUE(raycut_test::check_counts({1, 0}, ot).ok);
  EXPECT_FALSE(raycut_test::check_counts({2, 0}, ot).ok);
}

}  // namespace
