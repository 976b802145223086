// Small CPU calls stay fast on a machine whose cores are all busy: they run on the calling thread
// alone (include/raycut/detail/host_threads.hpp), so no OpenMP team waits for cores, and none
// spins on them. Before, a 108-atom call with a team took ~44 ms on 2 busy cores.
#include <gtest/gtest.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <random>
#include <thread>
#include <vector>

#include "raycut/box.hpp"
#include "raycut/engine.hpp"

namespace {

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
