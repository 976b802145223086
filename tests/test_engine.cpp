// The engine's contract at its edges: bad input is refused with what and where; N = 0, 1 and
// coincident particles are valid.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "core/validation.hpp"
#include "raycut/engine.hpp"
#include "raycut/pairs.hpp"
#include "raycut/tools/compare.hpp"
#include "raycut/tools/generators.hpp"

namespace {

using raycut::Engine;
using raycut::Error;
using raycut::ErrorCode;
using raycut::Kernel;
using raycut::MemorySpace;

// Runs `f`, expects raycut::Error with `code` and a message containing `needle`.
template <class F>
void expect_error(F&& f, ErrorCode code, const std::string& needle) {
  try {
    f();
    FAIL() << "no error thrown; expected one containing '" << needle << "'";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), code) << e.what();
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

std::vector<std::string> available_methods() {
  std::vector<std::string> names;
  for (const auto& m : raycut::list_methods())
    if (m.available) names.push_back(m.name);
  return names;
}

TEST(Engine, UnknownMethodIsRefusedWithTheKnownNames) {
  expect_error([] { Engine e("no-such-method"); }, ErrorCode::invalid_argument,
               "unknown method 'no-such-method'");
}

TEST(Engine, AutoPicksAnAvailableMethod) {
  Engine e("auto");
  bool found = false;
  for (const auto& m : raycut::list_methods()) found |= m.name == e.method() && m.available;
  EXPECT_TRUE(found) << e.method();
}

TEST(Engine, CapabilitiesOfUnknownMethodsAreRefused) {
  expect_error([] { raycut::method_capabilities("no-such-method"); }, ErrorCode::invalid_argument,
               "unknown method 'no-such-method'");
}

TEST(Engine, CapabilitiesOfAutoAreThoseOfTheMethodItPicks) {
  const auto picked = raycut::method_capabilities(raycut::auto_method());
  const auto given = raycut::method_capabilities("auto");
  EXPECT_EQ(given.periodic_boxes, picked.periodic_boxes);
  EXPECT_EQ(given.query_points, picked.query_points);
  EXPECT_EQ(given.pair_functors, picked.pair_functors);
}

// A functor that counts pairs, for the functor capability.
struct PairCounter {
  using Accumulator = std::uint32_t;
  std::uint32_t* count;
  void operator()(Accumulator& acc, std::uint32_t, std::uint32_t, raycut::Vec3, float) const {
    ++acc;
  }
  void finish(std::uint32_t i, Accumulator& acc) const { count[i] = acc; }
};

// What each available method declares is what it does: a periodic box, query points and a
// caller's functor are taken exactly when declared, refused with unsupported otherwise.
TEST(Engine, DeclaredCapabilitiesMatchWhatMethodsDo) {
  const std::vector<float> xyz = {0.5f, 0.5f, 0.5f, 1.0f, 0.5f, 0.5f, 3.8f, 0.5f, 0.5f};
  for (const std::string& name : available_methods()) {
    SCOPED_TRACE(name);
    const raycut::MethodCapabilities caps = raycut::method_capabilities(name);
    const auto outcome = [](auto&& f) {
      try {
        f();
        return true;
      } catch (const Error& e) {
        EXPECT_EQ(e.code(), ErrorCode::unsupported) << e.what();
        return false;
      }
    };
    EXPECT_EQ(caps.periodic_boxes, outcome([&] {
                Engine e(name);
                e.build({xyz.data(), 3, MemorySpace::host}, 1.0f,
                        raycut::Systems::periodic(raycut::Box::orthorhombic(4, 4, 4)));
                // 0.5 away, and 0.7 across the periodic face (3.3 in an open box)
                EXPECT_EQ(e.compute(Kernel::count).count[0], 2u);
              }));
    EXPECT_EQ(caps.query_points, outcome([&] {
                Engine e(name);
                raycut::Systems systems;
                systems.queries = {xyz.data(), 1, MemorySpace::host};
                e.build({xyz.data() + 3, 2, MemorySpace::host}, 1.0f, systems);
                EXPECT_EQ(e.compute(Kernel::count).count.size(), 1u);
              }));
    EXPECT_EQ(caps.pair_functors, outcome([&] {
                Engine e(name);
                e.build({xyz.data(), 3, MemorySpace::host}, 1.0f);
                if (e.space() != MemorySpace::host) return;  // a GPU functor needs nvcc
                std::vector<std::uint32_t> count(3);
                raycut::for_each_pair(e, PairCounter{count.data()});
                EXPECT_EQ(count[0], 1u);
              }));
  }
}

TEST(Engine, UnknownKernelNameIsRefused) {
  expect_error([] { raycut::parse_kernel("gravity"); }, ErrorCode::invalid_argument,
               "unknown kernel 'gravity'");
}

class EngineEdges : public ::testing::TestWithParam<std::string> {};

TEST_P(EngineEdges, NonFiniteCoordinateNamesTheFirstBadIndex) {
  std::vector<float> xyz(3 * 10, 0.5f);
  xyz[3 * 7 + 1] = std::numeric_limits<float>::quiet_NaN();
  xyz[3 * 9 + 2] = std::numeric_limits<float>::infinity();
  Engine e(GetParam());
  expect_error(
      [&] {
        e.build({xyz.data(), 10, MemorySpace::host}, 1.0f);
      },
      ErrorCode::invalid_input, "index 7");
  xyz[3 * 7 + 1] = 0.5f;
  expect_error(
      [&] {
        e.build({xyz.data(), 10, MemorySpace::host}, 1.0f);
      },
      ErrorCode::invalid_input, "index 9");
}

TEST_P(EngineEdges, BadCutoffIsRefused) {
  std::vector<float> xyz = {0, 0, 0, 1, 1, 1};
  Engine e(GetParam());
  for (float c : {0.0f, -1.0f, std::numeric_limits<float>::quiet_NaN(),
                  std::numeric_limits<float>::infinity()}) {
    expect_error(
        [&] {
          e.build({xyz.data(), 2, MemorySpace::host}, c);
        },
        ErrorCode::invalid_argument, "cutoff");
  }
}

TEST_P(EngineEdges, QueryBeforeBuildIsRefused) {
  Engine e(GetParam());
  expect_error([&] { e.run(Kernel::count); }, ErrorCode::invalid_argument, "before build");
  expect_error([&] { e.neighbours(); }, ErrorCode::invalid_argument, "before build");
}

TEST_P(EngineEdges, EmptyInputGivesNoPairs) {
  Engine e(GetParam());
  e.build({nullptr, 0, MemorySpace::host}, 1.0f);
  const auto r = e.compute(Kernel::count);
  EXPECT_TRUE(r.count.empty());
  const auto list = e.neighbours();
  ASSERT_EQ(list.offsets.size(), 1u);
  EXPECT_EQ(list.offsets[0], 0u);
  EXPECT_TRUE(list.indices.empty());
}

TEST_P(EngineEdges, SingleParticleHasNoNeighbour) {
  std::vector<float> xyz = {0.25f, -3.0f, 7.0f};
  Engine e(GetParam());
  e.build({xyz.data(), 1, MemorySpace::host}, 2.0f);
  const auto r = e.compute(Kernel::count);
  ASSERT_EQ(r.count.size(), 1u);
  EXPECT_EQ(r.count[0], 0u);
  const auto list = e.neighbours();
  EXPECT_EQ(list.offsets, (std::vector<std::uint64_t>{0, 0}));
}

TEST_P(EngineEdges, CoincidentParticlesAreNeighbours) {
  std::vector<float> xyz = {1, 2, 3, 1, 2, 3, 1, 2, 3};
  Engine e(GetParam());
  e.build({xyz.data(), 3, MemorySpace::host}, 0.5f);
  const auto r = e.compute(Kernel::count);
  EXPECT_EQ(r.count, (std::vector<std::uint32_t>{2, 2, 2}));
  const auto s = e.compute(Kernel::smooth);
  for (float energy : s.energy) EXPECT_FLOAT_EQ(energy, 2 * 0.25f * 0.25f);
}

TEST_P(EngineEdges, PairExactlyAtTheCutoffIsOutOfRange) {
  std::vector<float> xyz = {0, 0, 0, 0.5f, 0, 0, 0, 0.25f, 0};
  Engine e(GetParam());
  e.build({xyz.data(), 3, MemorySpace::host}, 0.5f);
  const auto r = e.compute(Kernel::count);
  EXPECT_EQ(r.count, (std::vector<std::uint32_t>{1, 0, 1}));
}

TEST_P(EngineEdges, LennardJonesOfOnePairMatchesTheFormula) {
  std::vector<float> xyz = {0, 0, 0, 1.5f, 0, 0};
  Engine e(GetParam());
  e.build({xyz.data(), 2, MemorySpace::host}, 2.0f);
  const auto r = e.compute(Kernel::lj);
  const double s6 = std::pow(1.0 / 1.5, 6);
  ASSERT_EQ(r.energy.size(), 2u);
  EXPECT_NEAR(r.energy[0], 4 * (s6 * s6 - s6), 1e-6);
  EXPECT_NEAR(r.energy[1], 4 * (s6 * s6 - s6), 1e-6);
}

// update() gives what a fresh build on the moved positions gives: refitted (small moves within
// the skin), rebuilt (moves beyond it), and with the default policy.
TEST_P(EngineEdges, UpdateMatchesAFreshBuild) {
  const raycut::PointCloud cloud = raycut::make_family("uniform", 3000, 1.0f, 5);
  for (float skin : {0.0f, 0.5f}) {
    for (float jitter : {0.1f, 2.0f}) {
      std::vector<float> moved = cloud.xyz;
      for (std::size_t k = 0; k < moved.size(); ++k)
        moved[k] += jitter * std::sin(0.7f * static_cast<float>(k));
      Engine engine(GetParam());
      engine.set_update_policy({skin});
      engine.build({cloud.xyz.data(), cloud.size(), MemorySpace::host}, 1.0f);
      engine.update({moved.data(), cloud.size(), MemorySpace::host});
      if (skin == 0.0f || jitter > skin / 2) {
        EXPECT_FALSE(engine.last_timings().refit);
      }
      Engine oracle("brute-force");
      oracle.build({moved.data(), cloud.size(), MemorySpace::host}, 1.0f);
      const auto diff = raycut::compare_neighbours(engine.neighbours(), oracle.neighbours());
      EXPECT_TRUE(diff.equal()) << "skin " << skin << " jitter " << jitter << ": "
                                << diff.first_difference;
      EXPECT_EQ(engine.compute(Kernel::count).count, oracle.compute(Kernel::count).count);
    }
  }
}

TEST_P(EngineEdges, UpdateNeedsTheSameParticleCount) {
  std::vector<float> xyz = {0, 0, 0, 1, 1, 1};
  Engine e(GetParam());
  e.build({xyz.data(), 2, MemorySpace::host}, 1.0f);
  expect_error(
      [&] {
        e.update({xyz.data(), 1, MemorySpace::host});
      },
      ErrorCode::invalid_argument, "needs the 2 particles");
}

// With query points (M targets over N sources): update() refuses (open builds too: it used to
// treat the first M new positions as one set and answer wrongly), sph_force refuses (its fields
// are read at both ends of a pair from one array), and the padded matrix pads with N, the
// invalid source index (it padded with M, a valid one when M < N). Found by adversarial
// tests.
TEST_P(EngineEdges, QueryPointsRefuseUpdateAndSphForceAndPadWithTheSourceCount) {
  std::vector<float> sources, queries;
  for (int i = 0; i < 50; ++i)
    for (float v : {0.1f * (i % 5), 0.1f * ((i / 5) % 5), 0.1f * (i / 25)}) sources.push_back(v);
  for (int q = 0; q < 3; ++q)
    for (float v : {0.15f + 0.1f * q, 0.2f, 0.05f}) queries.push_back(v);
  raycut::Systems systems;
  systems.queries = {queries.data(), 3, MemorySpace::host};
  Engine e(GetParam());
  try {
    e.build({sources.data(), 50, MemorySpace::host}, 0.3f, systems);
  } catch (const Error& err) {
    if (err.code() == ErrorCode::unsupported) GTEST_SKIP() << err.what();
    throw;
  }
  const std::vector<std::uint32_t> count = e.compute(Kernel::count).count;
  raycut::PaddedNeighbourBuffer padded;
  e.padded_neighbours(padded, {.k = 40});
  const std::vector<std::uint32_t> indices = padded.indices_to_host();
  for (std::size_t q = 0; q < 3; ++q) {
    ASSERT_GT(count[q], 0u);
    for (std::uint32_t c = 0; c < 40; ++c)
      if (c < count[q])
        EXPECT_LT(indices[40 * q + c], 50u) << "query " << q << " entry " << c;
      else
        EXPECT_EQ(indices[40 * q + c], 50u) << "query " << q << " padding " << c;
  }
  expect_error(
      [&] {
        e.update({sources.data(), 50, MemorySpace::host});
      },
      ErrorCode::unsupported, "query points");
  std::vector<float> velocity(3 * 50, 0.0f), density(50, 1.0f), pressure(50, 1.0f);
  raycut::KernelOptions options;
  options.sph_mass = 1.0f;
  options.sph = {velocity.data(), density.data(), pressure.data()};
  expect_error([&] { e.compute(Kernel::sph_force, options); }, ErrorCode::unsupported,
               "query points");
  // A non-finite query is named as a query point (it was "particle index 1": the wrong array).
  queries[3 * 1 + 2] = std::numeric_limits<float>::quiet_NaN();
  systems.queries = {queries.data(), 3, MemorySpace::host};
  expect_error(
      [&] {
        e.build({sources.data(), 50, MemorySpace::host}, 0.3f, systems);
      },
      ErrorCode::invalid_input, "query point index 1");
}

TEST(EngineMemory, AListLargerThanMemoryIsAClearError) {
  raycut::NeighbourList list;
  expect_error([&] { raycut::detail::allocate_indices(list, std::uint64_t{1} << 62); },
               ErrorCode::out_of_memory, "pairs need");
}

INSTANTIATE_TEST_SUITE_P(AllAvailable, EngineEdges, ::testing::ValuesIn(available_methods()),
                         [](const auto& info) {
                           std::string n = info.param;
                           for (char& c : n)
                             if (c == '-') c = '_';
                           return n;
                         });

}  // namespace
