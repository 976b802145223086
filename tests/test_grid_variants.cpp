// Every kernel and table path of the `grid` method (GridPolicy: a thread per target or grouped
// lanes; dense tables from a counting sort (in one block or several, placed by particle or by
// cell) or a radix sort; the compact
// table; reach 1 to 3) against the CPU brute force. The conformance suite runs `grid` with its
// automatic choices, which at its sizes always take the grouped kernel; this file makes every path
// meet the oracle. With periodic images, every path against the CPU cell list, whose pairs are
// exact at every box size (tests/test_periodic_exact.cpp): the float band decided in double.
#include <cuda_runtime.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <iterator>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "core/images.hpp"
#include "cuda/grid_policy.hpp"
#include "cuda/images.hpp"
#include "cuda/methods.hpp"
#include "raycut/engine.hpp"
#include "raycut/tools/compare.hpp"
#include "raycut/tools/generators.hpp"

namespace {

using raycut::Kernel;
namespace grid = raycut::detail::cuda;
using grid::GridPolicy;

struct Variant {
  const char* name;
  GridPolicy policy;
};

// k: cells C/k wide; lanes per target; layout 1 dense, 2 compact; dense_build and registers as
// numbered in grid::DenseBuild and grid::RegisterBudget (0: automatic).
GridPolicy make(int k, int lanes, int layout, int dense_build, int registers = 0) {
  GridPolicy o;
  o.registers = static_cast<grid::RegisterBudget>(registers);
  o.cell_width = static_cast<grid::CellWidth>(k);
  o.lanes = grid::lanes_per_target(lanes);
  o.layout = static_cast<grid::TableLayout>(layout);
  o.dense_build = static_cast<grid::DenseBuild>(dense_build);
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

using Triple = std::array<std::int64_t, 5>;  // (i, j, S)

// The half list's orientation: i < j, or i == j and S lexicographically positive.
bool half_orientation(const Triple& t) {
  if (t[0] != t[1]) return t[0] < t[1];
  for (int k = 2; k < 5; ++k)
    if (t[k] != 0) return t[k] > 0;
  return false;
}

// Each entry as (i, j, S), S zero where the list has none; sorted.
std::vector<Triple> triples(const raycut::NeighbourList& l) {
  std::vector<Triple> out;
  for (std::size_t i = 0; i + 1 < l.offsets.size(); ++i)
    for (std::uint64_t e = l.offsets[i]; e < l.offsets[i + 1]; ++e) {
      Triple t{static_cast<std::int64_t>(i), l.indices[e], 0, 0, 0};
      if (!l.shifts.empty())
        for (int a = 0; a < 3; ++a) t[2 + a] = l.shifts[3 * e + a];
      out.push_back(t);
    }
  std::sort(out.begin(), out.end());
  return out;
}

// The half list by the half stencil (ListOptions::any_row) of a built grid: the pairs of the
// full list `want`, each once, in the row of either of its particles. `scattered`: particles in
// random order, whose pairs between two home points the stencil leaves in the higher index's row
// about half the time (none there would mean that the stencil never ran). Pairs across a face
// keep the index's row, so a set with many particles on faces has fewer: 9 % at L / C = 1e5
// below, hence a bound of 1 in 20.
void expect_half_any_row(raycut::detail::Method& grid, const raycut::NeighbourList& want,
                         const std::string& what, bool scattered) {
  auto storage = grid.make_list_storage();
  grid.neighbours(*storage, {.half = true, .shifts = true, .any_row = true});
  std::vector<Triple> got, halved;
  std::size_t upper_rows = 0;
  for (const Triple& t : triples(storage->to_host())) {
    upper_rows += !half_orientation(t);
    got.push_back(half_orientation(t) ? t : Triple{t[1], t[0], -t[2], -t[3], -t[4]});
  }
  if (scattered && got.size() >= 100) {
    EXPECT_GT(upper_rows, got.size() / 20) << what << ": the half stencil kept the index's rows";
  }
  std::sort(got.begin(), got.end());
  for (const Triple& t : triples(want))
    if (half_orientation(t)) halved.push_back(t);
  ASSERT_EQ(got.size(), halved.size()) << what << ": any_row half list entries";
  EXPECT_TRUE(got == halved) << what << ": any_row half list is not the full list halved";
}

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
  const raycut::Results want_forces = oracle.compute(Kernel::lj_forces);
  const raycut::NeighbourList want_list = oracle.neighbours();

  float* xyz = nullptr;
  ASSERT_EQ(cudaMalloc(&xyz, cloud.xyz.size() * sizeof(float)), cudaSuccess);
  cudaMemcpy(xyz, cloud.xyz.data(), cloud.xyz.size() * sizeof(float), cudaMemcpyHostToDevice);
  auto grid = raycut::detail::cuda::make_grid_with(v.policy);
  grid->build(xyz, n, cloud.cutoff);
  grid->compute(Kernel::count, {});
  const auto got_count = grid->results().count;
  grid->compute(Kernel::lj, {});
  const auto got_lj = grid->results().energy;
  grid->compute(Kernel::lj_forces, {});
  const raycut::Results got_forces = grid->results();
  auto storage = grid->make_list_storage();
  grid->neighbours(*storage, {});
  const raycut::NeighbourList got_list = storage->to_host();
  expect_half_any_row(*grid, want_list, std::string(v.name) + " " + family, family == "uniform");
  cudaFree(xyz);

  const auto diff = raycut::compare_neighbours(got_list, want_list);
  ASSERT_TRUE(diff.equal()) << v.name << " " << family << ": " << diff.first_difference;
  ASSERT_EQ(got_forces.force.size(), 3 * n);
  ASSERT_EQ(got_forces.virial.size(), 6 * n);
  // Forces to round-off of the sum of the terms' magnitudes (they cancel: a sum can be far
  // smaller than its terms, and the device reciprocal differs from the host's by an ulp).
  for (std::size_t i = 0; i < n; ++i) {
    double scale = 0;
    for (std::uint64_t e = want_list.offsets[i]; e < want_list.offsets[i + 1]; ++e) {
      const std::uint32_t j = want_list.indices[e];
      double r2 = 0;
      for (int a = 0; a < 3; ++a) {
        const double d = static_cast<double>(cloud.xyz[3 * j + a]) - cloud.xyz[3 * i + a];
        r2 += d * d;
      }
      const double s6 = 1.0 / (r2 * r2 * r2);
      scale += 24 * s6 * (2 * s6 + 1) / std::sqrt(r2);
    }
    for (int a = 0; a < 3; ++a) {
      const float want = want_forces.force[3 * i + a];
      if (std::isfinite(want) && std::isfinite(scale)) {
        ASSERT_NEAR(got_forces.force[3 * i + a], want, 1e-4 * scale + 1e-30)
            << v.name << " " << family << " force of target " << i;
      }
    }
  }

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

// A skewed periodic box L = ratio (cutoff 1) holding random points, each with a partner within
// 1e-7 to 1e-2 of the cutoff (so the band is met at every ratio), some moved by whole boxes.
struct PeriodicCase {
  raycut::Box box;
  std::vector<float> xyz;
};
PeriodicCase periodic_case(double ratio, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  PeriodicCase c;
  for (int k = 0; k < 3; ++k) {
    c.box.cell[k][k] = ratio * (0.8 + 0.4 * unit(rng));
    for (int m = 0; m < k; ++m) c.box.cell[k][m] = 0.3 * ratio * (2 * unit(rng) - 1);
    c.box.pbc[k] = true;
  }
  for (int p = 0; p < 1500; ++p) {
    double base[3] = {0, 0, 0}, dir[3], norm = 0;
    for (int k = 0; k < 3; ++k) {
      const double f = unit(rng) < 0.3 ? 1 - 1e-9 * unit(rng) : unit(rng);  // many on a face
      for (int d = 0; d < 3; ++d) base[d] += f * c.box.cell[k][d];
    }
    for (double& v : dir) {
      v = 2 * unit(rng) - 1;
      norm += v * v;
    }
    norm = std::sqrt(norm);
    const double distance = 1 + (unit(rng) < 0.5 ? -1 : 1) * std::pow(10.0, -7 + 5 * unit(rng));
    const int moved = unit(rng) < 0.2 ? (unit(rng) < 0.5 ? -2 : 2) : 0;  // boxes along a
    for (int d = 0; d < 3; ++d)
      c.xyz.push_back(static_cast<float>(base[d] + moved * c.box.cell[0][d]));
    for (int d = 0; d < 3; ++d)
      c.xyz.push_back(static_cast<float>(base[d] + distance * dir[d] / norm));
  }
  return c;
}

class GridVariantsPeriodic : public ::testing::TestWithParam<int> {};

TEST_P(GridVariantsPeriodic, MatchTheExactCellList) {
  int devices = 0;
  if (cudaGetDeviceCount(&devices) != cudaSuccess || devices == 0) GTEST_SKIP() << "no CUDA device";
  const Variant& v = variants[GetParam()];
  const float cutoff = 1.0f;
  for (const double ratio : {3.0, 1e3, 1e5}) {
    const PeriodicCase c = periodic_case(ratio, 17 + static_cast<std::uint64_t>(ratio));
    const std::size_t n = c.xyz.size() / 3;
    raycut::Engine oracle("cell-list");
    oracle.build({c.xyz.data(), n, raycut::MemorySpace::host}, cutoff, c.box);
    const auto want_count = oracle.compute(Kernel::count).count;
    const raycut::NeighbourList want_list = oracle.neighbours({.shifts = true});

    float* xyz = nullptr;
    ASSERT_EQ(cudaMalloc(&xyz, c.xyz.size() * sizeof(float)), cudaSuccess);
    cudaMemcpy(xyz, c.xyz.data(), c.xyz.size() * sizeof(float), cudaMemcpyHostToDevice);
    const raycut::detail::ImagePlan plan =
        raycut::detail::plan_images(raycut::Systems::periodic(c.box), n, cutoff);
    auto images = raycut::detail::cuda::make_device_image_points();
    images->expand(plan, xyz, nullptr, nullptr);
    auto grid = raycut::detail::cuda::make_grid_with(v.policy);
    grid->build_points(images->points(), cutoff);
    grid->compute(Kernel::count, {});
    const auto got_count = grid->results().count;
    auto storage = grid->make_list_storage();
    grid->neighbours(*storage, {.shifts = true});
    const raycut::NeighbourList got_list = storage->to_host();
    expect_half_any_row(*grid, want_list, std::string(v.name) + ", L / C " + std::to_string(ratio),
                        true);
    cudaFree(xyz);

    const auto diff = raycut::compare_neighbours(got_list, want_list);
    ASSERT_TRUE(diff.equal()) << v.name << ", L / C " << ratio << ": " << diff.first_difference;
    ASSERT_EQ(got_count, want_count) << v.name << ", L / C " << ratio;
    EXPECT_GT(want_list.indices.size(), 0u) << "L / C " << ratio << ": no pairs to compare";
  }
}

INSTANTIATE_TEST_SUITE_P(Grid, GridVariantsPeriodic,
                         ::testing::Range(0, static_cast<int>(std::size(variants))),
                         [](const auto& info) { return std::string(variants[info.param].name); });

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
