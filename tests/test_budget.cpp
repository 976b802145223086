// Refusals that are clear and early: the host memory budget (RAYCUT_MAX_MEMORY, else the memory
// available and the cgroup's headroom), checked before lists and padded matrices are allocated;
// cutoffs checked as given in double; distances that agree with their vectors at every scale
// of the supported cutoff range; the padded report's largest row; a pass's per-thread sums that
// do not fit, left out for the pass that needs none.
#include <gtest/gtest.h>
#include <omp.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <string>
#include <vector>

#include "error_helpers.hpp"
#include "raycut/engine.hpp"
#include "raycut/host_memory.hpp"
#include "raycut/pairs.hpp"

namespace {

using raycut::Engine;
using raycut::ErrorCode;
using raycut::MemorySpace;
using raycut_test::contains;
using raycut_test::error_message;

// RAYCUT_MAX_MEMORY set for one test, restored after.
class Budget {
 public:
  explicit Budget(const char* value) {
    if (const char* old = std::getenv("RAYCUT_MAX_MEMORY")) old_ = old, had_ = true;
    ::setenv("RAYCUT_MAX_MEMORY", value, 1);
  }
  ~Budget() {
    if (had_)
      ::setenv("RAYCUT_MAX_MEMORY", old_.c_str(), 1);
    else
      ::unsetenv("RAYCUT_MAX_MEMORY");
  }

 private:
  std::string old_;
  bool had_ = false;
};

std::vector<std::string> cpu_methods() {
  std::vector<std::string> out;
  for (const auto& m : raycut::list_methods())
    if (m.available && Engine(m.name).space() == MemorySpace::host) out.push_back(m.name);
  return out;
}

// n points in the unit cube from a fixed 64-bit LCG: the same cloud on every machine.
std::vector<float> unit_cube_cloud(std::size_t n) {
  std::vector<float> xyz(3 * n);
  std::uint64_t state = 12345;
  for (float& v : xyz) {
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    v = static_cast<float>(state >> 40) / static_cast<float>(1 << 24);
  }
  return xyz;
}

TEST(MemoryBudget, EnvironmentValueWithSuffixes) {
  {
    Budget b("300M");
    EXPECT_EQ(raycut::host_memory_budget().bytes, 300.0 * 1024 * 1024);
    EXPECT_TRUE(raycut::host_memory_budget().from_environment);
  }
  {
    Budget b("2.5G");
    EXPECT_EQ(raycut::host_memory_budget().bytes, 2.5 * 1024 * 1024 * 1024);
  }
  {
    Budget b("64KiB");
    EXPECT_EQ(raycut::host_memory_budget().bytes, 64.0 * 1024);
  }
  {
    Budget b("123456");
    EXPECT_EQ(raycut::host_memory_budget().bytes, 123456.0);
  }
}

TEST(MemoryBudget, MalformedValueNamesTheVariable) {
  for (const char* bad : {"abc", "12Q", "-5M", "0", "1.2.3G", "M"}) {
    Budget b(bad);
    const std::string message =
        error_message(ErrorCode::invalid_argument, [] { raycut::host_memory_budget(); });
    EXPECT_TRUE(contains(message, "RAYCUT_MAX_MEMORY")) << message;
    EXPECT_TRUE(contains(message, std::string("'") + bad + "'")) << message;
    EXPECT_TRUE(contains(message, "K, M, G or T")) << message;
  }
}

TEST(MemoryBudget, SystemBudgetIsPositiveAndSaysWhereItComesFrom) {
  ::unsetenv("RAYCUT_MAX_MEMORY");
  const raycut::MemoryBudget budget = raycut::host_memory_budget();
  EXPECT_GT(budget.bytes, 0.0);
  EXPECT_FALSE(budget.from_environment);
  EXPECT_TRUE(contains(budget.source, "MemAvailable")) << budget.source;
}

TEST(MemoryBudget, RequestAboveBudgetNamesSizeBudgetAndKnob) {
  Budget b("300M");
  raycut::require_host_memory(299.0 * 1024 * 1024, "a small request");
  const std::string message = error_message(
      ErrorCode::out_of_memory, [] { raycut::require_host_memory(2.3e9, "a neighbour list"); });
  EXPECT_TRUE(contains(message, "a neighbour list needs 2.14 GiB")) << message;
  EXPECT_TRUE(contains(message, "300.00 MiB")) << message;
  EXPECT_TRUE(contains(message, "RAYCUT_MAX_MEMORY=300M")) << message;
}

// 12,000 points in a cube of side 1 with cutoff 10: every pair, 1.44e8 entries (~0.54 GiB of
// indices alone, 2.1 GiB as COO with distances): refused before the fill allocates, quickly.
TEST(MemoryBudget, ListLargerThanTheBudgetIsRefusedBeforeAllocation) {
  Budget b("300M");
  const std::size_t n = 12000;
  std::vector<float> xyz(3 * n);
  for (std::size_t i = 0; i < xyz.size(); ++i)
    xyz[i] = static_cast<float>((i * 7919) % 1000) / 1000;
  for (const std::string& method : cpu_methods()) {
    Engine engine(method);
    engine.build({xyz.data(), n, MemorySpace::host}, 10.0f);
    const auto start = std::chrono::steady_clock::now();
    const std::string message = error_message(ErrorCode::out_of_memory, [&] {
      engine.neighbours(raycut::ListOptions{.distances = true});
    });
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    EXPECT_TRUE(contains(message, "143988000 pairs")) << method << ": " << message;
    EXPECT_TRUE(contains(message, "RAYCUT_MAX_MEMORY=300M")) << message;
    EXPECT_LT(seconds, 20.0) << method << ": the refusal comes after the count pass only";
  }
}

// A list within the budget whose rows would not fit it if made in one pass (the rows take as
// much again, and grow by doubling: 23 MB of list, rows growing from 16.8 to 33.5 MB against a
// budget of 31.5 MB): made in two passes instead, the same list, and no error.
TEST(MemoryBudget, ListWhoseOnePassRowsPassTheBudgetIsMadeInTwoPasses) {
  const std::size_t n = 20000;
  const std::vector<float> xyz = unit_cube_cloud(n);
  const raycut::ListOptions options{.distances = true};
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);  // one thread's rows: the growth above, whatever the machine
  Engine engine("cell-list");
  engine.build({xyz.data(), n, MemorySpace::host}, 0.125f);
  const raycut::NeighbourList unbudgeted = engine.neighbours(options);
  // More entries than 2^21 (the rows then double to 2^22: 33.5 MB), within the budget.
  ASSERT_GT(unbudgeted.indices.size(), std::size_t{1} << 21);
  ASSERT_LT(unbudgeted.indices.size() * 8.0, 28e6);
  raycut::NeighbourList budgeted;
  {
    Budget b("30M");
    Engine tight("cell-list");
    tight.build({xyz.data(), n, MemorySpace::host}, 0.125f);
    budgeted = tight.neighbours(options);
    EXPECT_EQ(tight.neighbours(options).indices, budgeted.indices);  // the next list, too
  }
  omp_set_num_threads(threads);
  EXPECT_EQ(budgeted.offsets, unbudgeted.offsets);
  EXPECT_EQ(budgeted.indices, unbudgeted.indices);
  EXPECT_EQ(budgeted.distances, unbudgeted.distances);
}

// lj_forces from both sides of each pair: the built-in functor less option::mirror.
struct LjForcesEachSide {
  raycut::LennardJonesForceKernel lj;
  using Accumulator = raycut::LennardJonesForceKernel::Accumulator;
  void operator()(Accumulator& acc, std::uint32_t i, raycut::Vec3 r, float r2) const {
    lj(acc, i, r, r2);
  }
  void finish(std::uint32_t i, Accumulator& acc) const { lj.finish(i, acc); }
};

// The cell list computes lj_forces once per pair into per-thread sums (40 bytes a particle and
// thread); where those would leave less than as much again of the budget, it computes each pair
// from both sides instead, which needs no sums: the same bits as that pass, not a refusal.
TEST(MemoryBudget, PerThreadSumsBeyondTheBudgetFallBackToEachSide) {
  const std::size_t n = 20000;  // 800 kB of sums on one thread
  const std::vector<float> xyz = unit_cube_cloud(n);
  const int threads = omp_get_max_threads();
  omp_set_num_threads(1);
  Engine engine("cell-list");
  engine.build({xyz.data(), n, MemorySpace::host}, 0.05f);
  raycut::KernelOptions lj;
  lj.lj_sigma = 0.005f;  // below the spacing (~0.04): finite forces
  const raycut::Results once = engine.compute(raycut::Kernel::lj_forces, lj);
  std::vector<float> energy(n), force(3 * n), virial(6 * n);
  const raycut::KernelOutputs out{nullptr, energy.data(), force.data(), virial.data()};
  raycut::for_each_pair(
      engine, LjForcesEachSide{raycut::LennardJonesForceSpec::make(lj, 0.05f * 0.05f, out)});
  raycut::Results budgeted;
  {
    Budget b("1M");
    budgeted = engine.compute(raycut::Kernel::lj_forces, lj);
  }
  omp_set_num_threads(threads);
  EXPECT_EQ(budgeted.force, force);
  EXPECT_EQ(budgeted.energy, energy);
  EXPECT_EQ(budgeted.virial, virial);
  EXPECT_NE(once.force, force);  // the pass without the budget took each pair once
  for (std::size_t k = 0; k < force.size(); ++k)
    ASSERT_NEAR(once.force[k], force[k], 1e-4 * std::abs(force[k]) + 1e-3) << "component " << k;
}

// A GPU list fits the device but not the host budget: its copy to the host (what NumPy outputs
// and Engine::neighbours(options) hand back) is refused before it allocates.
TEST(MemoryBudget, HostCopyOfADeviceListBeyondTheBudgetIsRefused) {
  if (!raycut::cuda_device_available()) GTEST_SKIP() << "no CUDA device";
  const std::size_t n = 20000;
  const std::vector<float> xyz = unit_cube_cloud(n);
  const raycut::ListOptions options{.distances = true};
  Engine engine("grid");
  engine.build({xyz.data(), n, MemorySpace::host}, 0.125f);
  const std::size_t pairs = engine.neighbours(options).indices.size();
  ASSERT_GT(pairs * 8.0, 20.0 * 1024 * 1024);  // above the 16 MiB that is never compared
  Budget b("20M");
  const std::string message =
      error_message(ErrorCode::out_of_memory, [&] { (void)engine.neighbours(options); });
  EXPECT_TRUE(contains(message, "a host copy of a neighbour list of " + std::to_string(pairs)))
      << message;
  EXPECT_TRUE(contains(message, "RAYCUT_MAX_MEMORY=20M")) << message;
}

TEST(MemoryBudget, PaddedKFarAboveNIsRefusedNamingTheKThatIsEnough) {
  const std::size_t n = 50;
  std::vector<float> xyz(3 * n);
  for (std::size_t i = 0; i < xyz.size(); ++i) xyz[i] = static_cast<float>(i % 17) / 17;
  for (const char* budget : {"300M", ""}) {  // "": the system's budget (400 GiB is above it)
    Budget b(budget);
    for (const std::string& method : cpu_methods()) {
      Engine engine(method);
      engine.build({xyz.data(), n, MemorySpace::host}, 0.3f);
      raycut::PaddedNeighbourBuffer padded;
      const std::string message = error_message(ErrorCode::out_of_memory, [&] {
        engine.padded_neighbours(padded, {.k = std::uint32_t{1} << 31});
      });
      EXPECT_TRUE(contains(message, "K = 2147483648")) << message;
      EXPECT_TRUE(contains(message, "K = 50 is always enough")) << message;
      EXPECT_TRUE(contains(message, "RAYCUT_MAX_MEMORY")) << message;
    }
  }
}

TEST(MemoryBudget, BuildBeyondTheBudgetIsRefusedBeforeItAllocates) {
  Budget b("1M");
  const std::size_t n = 20000;  // ~1.5 MiB of structure at ~80 B a point
  std::vector<float> xyz(3 * n, 0.5f);
  for (const std::string& method : cpu_methods()) {
    Engine engine(method);
    const std::string message = error_message(ErrorCode::out_of_memory, [&] {
      engine.build({xyz.data(), n, MemorySpace::host}, 0.1f);
    });
    EXPECT_TRUE(contains(message, "method '" + method + "' over 20000 points")) << message;
    EXPECT_TRUE(contains(message, "RAYCUT_MAX_MEMORY=1M")) << message;
  }
}

// A box far thinner than the cutoff: 10 particles in a unit box at C = 200 make ~6.4e8 image
// points (~65 GiB with the structure over them), refused before any is placed.
TEST(MemoryBudget, PeriodicImagesBeyondTheBudgetAreRefusedBeforeTheyAreMade) {
  Budget b("300M");
  std::vector<float> xyz;
  for (int p = 0; p < 10; ++p)
    for (int a = 0; a < 3; ++a) xyz.push_back(0.05f + 0.09f * p + 0.01f * a);
  raycut::Box box;
  for (int a = 0; a < 3; ++a) box.cell[a][a] = 1.0, box.pbc[a] = true;
  for (const std::string& method : cpu_methods()) {
    Engine engine(method);
    const auto start = std::chrono::steady_clock::now();
    const std::string message = error_message(ErrorCode::out_of_memory, [&] {
      engine.build({xyz.data(), 10, MemorySpace::host}, 200.0f, box);
    });
    EXPECT_TRUE(contains(message, "periodic images")) << message;
    EXPECT_TRUE(contains(message, "for 10 targets")) << message;
    EXPECT_TRUE(contains(message, "RAYCUT_MAX_MEMORY=300M")) << message;
    EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(5)) << method;
  }
}

TEST(PaddedReport, LargestCountIsTheLargestRowWithoutOverflow) {
  // Particle 0 has 3 neighbours, the others 1 each.
  const std::vector<float> xyz = {0, 0, 0, 0.5f, 0, 0, 0, 0.5f, 0, 0, 0, 0.5f};
  for (const std::string& method : cpu_methods()) {
    Engine engine(method);
    engine.build({xyz.data(), 4, MemorySpace::host}, 0.6f);
    raycut::PaddedNeighbourBuffer padded;
    const raycut::PaddedReport report = engine.padded_neighbours(padded, {.k = 8});
    EXPECT_FALSE(report.overflowed());
    EXPECT_EQ(report.largest_count, 3u) << method;
    EXPECT_EQ(engine.padded_neighbours(padded, {.k = 2}).largest_count, 3u) << method;
  }
}

TEST(Cutoff, CheckedAsGivenInDouble) {
  for (double bad : {1e-50, 1e39}) {
    const std::string message =
        error_message(ErrorCode::invalid_argument, [&] { raycut::checked_cutoff(bad); });
    EXPECT_TRUE(contains(message, "[2^-60, 2^60]")) << message;
    EXPECT_TRUE(contains(message, bad < 1 ? "1e-50" : "1e+39")) << message;
  }
  EXPECT_EQ(raycut::checked_cutoff(0.25), 0.25f);
}

// d is |D| to float precision at every scale the cutoff range allows, pairs 2^-149 to 2^60
// apart (before: sqrtf of the predicate's r2, subnormal below ~1e-19, so a pair 1e-22 apart
// had d off by 1 %).
TEST(Distances, EqualTheLengthOfTheirVectorsAtEveryScale) {
  for (const std::string& method : cpu_methods()) {
    for (double separation : {1e-45, 3e-40, 1e-30, 1e-22, 1e-20, 1e-10, 1.0, 1e10, 2e17}) {
      const double cutoff = std::max(separation * 4, 1e-18);
      // Three components of different sizes, the largest `separation`.
      const float dx = static_cast<float>(separation), dy = static_cast<float>(separation * 0.6),
                  dz = static_cast<float>(separation * 0.3);
      const std::vector<float> xyz = {0, 0, 0, dx, dy, dz};
      Engine engine(method);
      engine.build({xyz.data(), 2, MemorySpace::host}, static_cast<float>(cutoff));
      const raycut::NeighbourList list =
          engine.neighbours(raycut::ListOptions{.distances = true, .vectors = true});
      ASSERT_EQ(list.indices.size(), 2u) << method << " at " << separation;
      for (std::size_t e = 0; e < 2; ++e) {
        const double x = list.vectors[3 * e], y = list.vectors[3 * e + 1],
                     z = list.vectors[3 * e + 2];
        const double length = std::sqrt(x * x + y * y + z * z);
        const double ulp = std::max(std::ldexp(1.0, -149), length * std::ldexp(1.0, -22));
        EXPECT_NEAR(list.distances[e], length, ulp) << method << " at separation " << separation;
      }
    }
  }
}

}  // namespace
