// Small CPU calls stay fast on a machine whose cores are all busy: they run on the calling thread
// alone (include/raycut/detail/host_threads.hpp), so no OpenMP team waits for cores, and none
// spins on them. Before, a 108-atom call with a team took ~44 ms on 2 busy cores. And they enter
// no OpenMP region at all: a region with a false `if` clause still ends in a barrier whose futex
// wake is a system call (seven of them in a 1-atom cell's list). Counted through GOMP_parallel,
// GCC's entry to every parallel region, defined here to count and forward to libgomp's.
#include <dlfcn.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstddef>
#include <random>
#include <thread>
#include <vector>

#include "raycut/box.hpp"
#include "raycut/engine.hpp"

namespace {
std::atomic<long> parallel_regions{0};
}  // namespace

extern "C" void GOMP_parallel(void (*fn)(void*), void* data, unsigned threads, unsigned flags) {
  using Entry = void (*)(void (*)(void*), void*, unsigned, unsigned);
  static const auto libgomp = reinterpret_cast<Entry>(dlsym(RTLD_NEXT, "GOMP_parallel"));
  parallel_regions.fetch_add(1);
  libgomp(fn, data, threads, flags);
}

namespace {

// Periodic random points at the LJ liquid's density, n of them, cutoff 2.5.
struct Liquid {
  std::vector<float> xyz;
  raycut::Box box;
  explicit Liquid(std::size_t n) : xyz(3 * n) {
    const double side = std::cbrt(static_cast<double>(n) / 0.8442);
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(0.0, side);
    for (float& v : xyz) v = static_cast<float>(u(rng));
    for (int k = 0; k < 3; ++k) {
      box.cell[k][k] = side;
      box.pbc[k] = true;
    }
  }
  // Parallel regions entered by a build and a list with S, and by lj_forces.
  long regions(const char* method) const {
    raycut::Engine engine(method);
    const long before = parallel_regions.load();
    engine.build({xyz.data(), xyz.size() / 3, raycut::MemorySpace::host}, 2.5f, box);
    EXPECT_GT(engine.neighbours({.shifts = true}).indices.size(), 0u);
    engine.compute(raycut::Kernel::lj_forces);
    return parallel_regions.load() - before;
  }
};

TEST(HostThreads, SmallCallsEnterNoParallelRegion) {
  // The counter counts: a call large enough for a team enters regions (else this runtime is not
  // libgomp, whose entry is counted here).
  if (Liquid(20000).regions("cell-list") == 0)
    GTEST_SKIP() << "no GOMP_parallel call counted: not GCC's OpenMP runtime";
  for (const char* method : {"cell-list", "brute-force"})
    for (std::size_t n : {1, 108, 1000})
      EXPECT_EQ(Liquid(n).regions(method), 0) << method << ", " << n << " particles";
}

TEST(HostThreads, SmallPeriodicCallOnBusyCoresTakesUnderTwoMilliseconds) {
  // 108 atoms of an fcc-like liquid: a periodic cube of 3 C, random positions.
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> u(0.0f, 7.5f);
  std::vector<float> xyz(3 * 108);
  for (float& v : xyz) v = u(rng);
  raycut::Box box;
  for (int k = 0; k < 3; ++k) {
    box.cell[k][k] = 7.5;
    box.pbc[k] = true;
  }
  raycut::Engine engine("cell-list");
  const auto call = [&] {
    engine.build({xyz.data(), 108, raycut::MemorySpace::host}, 2.5f, box);
    return engine.neighbours({.shifts = true}).indices.size();
  };
  const std::size_t pairs = call();
  ASSERT_GT(pairs, 0u);

  // Every core busy with a spinning thread, as on a loaded machine.
  std::atomic<bool> stop{false};
  std::vector<std::thread> load;
  for (unsigned t = 0; t < std::max(1u, std::thread::hardware_concurrency()); ++t)
    load.emplace_back([&] {
      volatile unsigned long spin = 0;
      while (!stop.load(std::memory_order_relaxed)) spin = spin + 1;
    });
  std::vector<double> ms;
  for (int r = 0; r < 31; ++r) {
    const auto start = std::chrono::steady_clock::now();
    EXPECT_EQ(call(), pairs);
    ms.push_back(std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
                     .count());
  }
  stop = true;
  for (std::thread& t : load) t.join();
  std::sort(ms.begin(), ms.end());
  EXPECT_LT(ms[ms.size() / 2], 2.0) << "median of 31 calls; fastest " << ms.front() << " ms";
}

}  // namespace
