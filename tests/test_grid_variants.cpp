// Every kernel and table path of the `grid` method (GridOptions: a thread per target or grouped
// lanes; dense tables from a counting sort (in one block or several, placed by particle or by
// cell) or a radix sort; the compact
// table; reach 1 to 3) against the CPU brute force. The conformance suite runs `grid` with its
// automatic choices, which at its sizes always take the grouped kernel; this file makes every path
// meet the oracle.
#include <cuda_runtime.h>
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <iterator>
#include <string>
#include <tuple>
#include <vector>

#include "cuda/methods.hpp"
#include "raycut/engine.hpp"
#include "raycut/generators.hpp"

namespace {

using raycut::Kernel;
using raycut::detail::cuda::GridOptions;

struct Variant {
  const char* name;
  GridOptions options;
};

GridOptions make(int k, int lanes, int layout, int dense_build, int registers = 0) {
  GridOptions o;
  o.thread_registers = registers;
  o.cells_per_cutoff = k;
  o.lanes_per_target = lanes;
  o.layout = layout;
  o.dense_build = dense_build;
  return o;
}

const Variant variants[] = {
    {"thread_k1_counting", make(1, 1, 1, 1)},
    {"thread_k2_radix", make(2, 1, 1, 2)},
    {"thread_k3_counting", make(3, 1, 1, 1)},
    {"thread_k2_compact", make(2, 1, 2, 0)},
    {"thread_k1_compact", make(1, 1, 2, 0)},
    {"group4_k2_counting", make(2, 4, 1, 1)},
    {"group8_k1_radix", make(1, 8, 1, 2)},
    {"group16_k1_compact", make(1, 16, 2, 0)},
    {"group32_k3_radix", make(3, 32, 1, 2)},
    {"group16_k2_oneblock", make(2, 16, 1, 3)},
    {"thread_k1_oneblock", make(1, 1, 1, 3)},
    {"thread_k1_bycell", make(1, 1, 1, 4)},
    {"group8_k2_bycell", make(2, 8, 1, 4)},
    {"thread_k2_counting_regs1", make(2, 1, 1, 1, 1)},
    {"thread_k1_compact_regs2", make(1, 1, 2, 0, 2)},
};

const char* families[] = {"uniform",          "lattice-k2",     "coincident",
                          "gaussian-outlier", "sphere-surface", "diagonal"};

class GridVariants : public ::testing::TestWithParam<std::tuple<int, int>> {};

TEST_P(GridVariants, MatchBruteForce) {
  int devices = 0;
  if (cudaGetDeviceCount(&devices) != cudaSuccess || devices == 0) GTEST_SKIP() << "no CUDA device";
  const Variant& v = variants[std::get<0>(GetParam())];
  const std::string family = families[std::get<1>(GetParam())];
  const raycut::PointCloud cloud = raycut::make_family(family, 3001, 0.37f, 7);
  const std::size_t n = cloud.size();

  raycut::Engine oracle("brute-force");
  oracle.build({cloud.xyz.data(), n, raycut::MemorySpace::host}, cloud.cutoff);
  const auto want_count = oracle.compute(Kernel::count).count;
  const auto want_lj = oracle.compute(Kernel::lj).energy;

  float* xyz = nullptr;
  ASSERT_EQ(cudaMalloc(&xyz, cloud.xyz.size() * sizeof(float)), cudaSuccess);
  cudaMemcpy(xyz, cloud.xyz.data(), cloud.xyz.size() * sizeof(float), cudaMemcpyHostToDevice);
  auto grid = raycut::detail::cuda::make_grid_with(v.options);
  grid->build(xyz, n, cloud.cutoff);
  grid->compute(Kernel::count, {});
  const auto got_count = grid->results().count;
  grid->compute(Kernel::lj, {});
  const auto got_lj = grid->results().energy;
  cudaFree(xyz);

  ASSERT_EQ(got_count.size(), n);
  ASSERT_EQ(got_lj.size(), n);
  for (std::size_t i = 0; i < n; ++i) {
    ASSERT_EQ(got_count[i], want_count[i]) << v.name << " " << family << " target " << i;
    const float tol = 1e-4f * std::abs(want_lj[i]) + 1e-30f;
    if (std::isfinite(want_lj[i]))  // coincident pairs make inf - inf = NaN on both sides
      ASSERT_NEAR(got_lj[i], want_lj[i], tol) << v.name << " " << family << " target " << i;
    else
      ASSERT_FALSE(std::isfinite(got_lj[i])) << v.name << " " << family << " target " << i;
  }
}

INSTANTIATE_TEST_SUITE_P(
    Grid, GridVariants,
    ::testing::Combine(::testing::Range(0, static_cast<int>(std::size(variants))),
                       ::testing::Range(0, static_cast<int>(std::size(families)))),
    [](const auto& info) {
      std::string name = std::string(variants[std::get<0>(info.param)].name) + "_" +
                         families[std::get<1>(info.param)];
      for (char& c : name)
        if (c == '-') c = '_';
      return name;
    });

}  // namespace

// Positions at a 16-byte boundary are read as float4 by the bounding box, others one float at a
// time: both must give the same grid, hence the same neighbours.
TEST(GridBoundingBox, AnyAlignmentGivesTheSameNeighbours) {
  int devices = 0;
  if (cudaGetDeviceCount(&devices) != cudaSuccess || devices == 0) GTEST_SKIP() << "no CUDA device";
  const raycut::PointCloud cloud = raycut::make_family("uniform", 3001, 0.37f, 7);
  const std::size_t n = cloud.size(), bytes = cloud.xyz.size() * sizeof(float);
  float* buffer = nullptr;
  ASSERT_EQ(cudaMalloc(&buffer, bytes + 4 * sizeof(float)), cudaSuccess);
  std::vector<std::vector<std::uint32_t>> counts;
  for (int offset : {0, 1, 2, 3}) {  // floats past a 16-byte boundary
    cudaMemcpy(buffer + offset, cloud.xyz.data(), bytes, cudaMemcpyHostToDevice);
    auto grid = raycut::detail::cuda::make_grid();
    grid->build(buffer + offset, n, cloud.cutoff);
    grid->compute(Kernel::count, {});
    counts.push_back(grid->results().count);
  }
  cudaFree(buffer);
  for (int offset = 1; offset < 4; ++offset) EXPECT_EQ(counts[offset], counts[0]) << offset;
  std::uint64_t pairs = 0;
  for (auto c : counts[0]) pairs += c;
  EXPECT_GT(pairs, 0u);
}
