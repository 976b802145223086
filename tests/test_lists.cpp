// The list API around the one pair pass, on every available method: reusable buffers, the Verlet
// list (skin reuse gives every pair a rebuild gives), N = 0, a moved-from Engine, a failed run.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "raycut/engine.hpp"
#include "raycut/tools/compare.hpp"
#include "raycut/tools/device_array.hpp"
#include "raycut/tools/generators.hpp"

#if defined(RAYCUT_TESTS_CUDA)
#include "cuda/runtime.hpp"  // download(): taken device results read back
#endif

namespace {

using raycut::Engine;
using raycut::Kernel;
using raycut::MemorySpace;

std::vector<std::string> available_methods() {
  std::vector<std::string> names;
  for (const auto& m : raycut::list_methods())
    if (m.available) names.push_back(m.name);
  return names;
}

class Lists : public ::testing::TestWithParam<std::string> {};

TEST_P(Lists, PreparedBufferAllocatesOnce) {
  const raycut::PointCloud cloud = raycut::make_family("uniform", 3000, 1.0f, 5);
  Engine engine(GetParam());
  engine.build({cloud.xyz.data(), cloud.size(), MemorySpace::host}, 1.0f);
  raycut::NeighbourListBuffer buffer;
  engine.neighbours(buffer, {false, true, true});
  const std::size_t bytes = buffer.bytes();
  const auto first = buffer.to_host();
  engine.neighbours(buffer, {false, true, true});
  EXPECT_EQ(buffer.bytes(), bytes);
  EXPECT_EQ(buffer.to_host().indices, first.indices);
  EXPECT_EQ(buffer.size(), cloud.size());
  EXPECT_EQ(buffer.pairs(), first.indices.size());
  EXPECT_GT(buffer.pairs(), 0u);
}

// One engine asked for every set of outputs in turn (some the same size per entry: S and D), as
// a step loop of several models would: each list equals that of an engine asked once.
TEST_P(Lists, EveryOutputSetInTurnOnOneEngine) {
  const raycut::PointCloud cloud = raycut::make_family("uniform", 2000, 1.0f, 9);
  const raycut::Systems box = raycut::Systems::periodic(raycut::Box::orthorhombic(1, 1, 1));
  Engine engine(GetParam());
  if (!raycut::method_capabilities(GetParam()).periodic_boxes) GTEST_SKIP() << "no periodic boxes";
  engine.build({cloud.xyz.data(), cloud.size(), MemorySpace::host}, 0.15f, box);
  // Bits: 1 distances, 2 vectors, 4 shifts, 8 half. S after D and D after S: the same bytes.
  const int order[] = {4, 2, 5, 3, 6, 1, 0, 7, 12, 10, 13, 11, 14, 9, 8, 15};
  for (int round = 0; round < 2; ++round)
    for (const int set : order) {
      const raycut::ListOptions options{.half = (set & 8) != 0,
                                        .distances = (set & 1) != 0,
                                        .vectors = (set & 2) != 0,
                                        .shifts = (set & 4) != 0};
      Engine fresh(GetParam());
      fresh.build({cloud.xyz.data(), cloud.size(), MemorySpace::host}, 0.15f, box);
      const raycut::NeighbourList expected = fresh.neighbours(options);
      const raycut::NeighbourList got = engine.neighbours(options);
      ASSERT_GT(expected.indices.size(), 0u);
      EXPECT_EQ(got.offsets, expected.offsets) << "set " << set;
      EXPECT_EQ(got.indices, expected.indices) << "set " << set;
      EXPECT_EQ(got.distances, expected.distances) << "set " << set;
      EXPECT_EQ(got.vectors, expected.vectors) << "set " << set;
      EXPECT_EQ(got.shifts, expected.shifts) << "set " << set;
    }
}

TEST_P(Lists, EmptyAndSingleParticle) {
  for (std::size_t n : {0, 1}) {
    const std::vector<float> xyz(3 * n, 0.5f);
    Engine engine(GetParam());
    engine.build({xyz.data(), n, MemorySpace::host}, 1.0f);
    raycut::NeighbourListBuffer buffer;
    engine.neighbours(buffer, {true, true, true});
    const raycut::NeighbourList list = buffer.to_host();
    ASSERT_EQ(list.offsets, std::vector<std::uint64_t>(n + 1, 0));
    EXPECT_TRUE(list.indices.empty());
    raycut::PaddedNeighbourBuffer padded;
    EXPECT_FALSE(engine.padded_neighbours(padded, {.k = 4}).overflowed());
    EXPECT_EQ(padded.counts_to_host(), std::vector<std::uint32_t>(n, 0));
  }
}

// A Verlet list built at C + skin keeps every pair within C while no particle moved more than
// skin / 2, and rebuilds once one has.
TEST_P(Lists, VerletSkinReuseKeepsEveryPairWithinTheCutoff) {
  const float cutoff = 1.0f, skin = 0.3f;
  raycut::PointCloud cloud = raycut::make_family("uniform", 2000, cutoff, 11);
  raycut::VerletList verlet(GetParam(), cutoff, skin);
  EXPECT_TRUE(verlet.update({cloud.xyz.data(), cloud.size(), MemorySpace::host}));
  std::uint64_t rebuilt_at = 0;
  for (int step = 1; step <= 12; ++step) {
    // Every particle moves 0.04 a step along a fixed direction: skin / 2 = 0.15 is passed at
    // step 4 (0.16 from the build).
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      const float angle = 0.7f * static_cast<float>(i);
      cloud.xyz[3 * i] += 0.04f * std::cos(angle);
      cloud.xyz[3 * i + 1] += 0.04f * std::sin(angle);
    }
    const bool rebuilt = verlet.update({cloud.xyz.data(), cloud.size(), MemorySpace::host});
    if (rebuilt && rebuilt_at == 0) rebuilt_at = step;
    // Every pair within C now is in the list (the list may hold more: it is at C + skin).
    Engine exact("brute-force");
    exact.build({cloud.xyz.data(), cloud.size(), MemorySpace::host}, cutoff);
    const raycut::NeighbourList want = exact.neighbours();
    const raycut::NeighbourList have = verlet.list().to_host();
    for (std::size_t i = 0; i < cloud.size(); ++i) {
      std::vector<std::uint32_t> row(have.indices.begin() + have.offsets[i],
                                     have.indices.begin() + have.offsets[i + 1]);
      std::sort(row.begin(), row.end());
      for (std::uint64_t e = want.offsets[i]; e < want.offsets[i + 1]; ++e)
        ASSERT_TRUE(std::binary_search(row.begin(), row.end(), want.indices[e]))
            << "step " << step << ": pair " << i << "," << want.indices[e] << " missing";
    }
    if (rebuilt) {  // just rebuilt: exactly the list at C + skin
      Engine wide("brute-force");
      wide.build({cloud.xyz.data(), cloud.size(), MemorySpace::host}, cutoff + skin);
      const auto diff = raycut::compare_neighbours(have, wide.neighbours());
      ASSERT_TRUE(diff.equal()) << "step " << step << ": " << diff.first_difference;
    }
  }
  EXPECT_EQ(rebuilt_at, 4u);
  EXPECT_GE(verlet.rebuilds(), 3u);  // at steps 4, 8, 12
  EXPECT_LE(verlet.rebuilds(), 4u);
}

// An update that moved nothing but holds a non-finite coordinate is refused, naming its particle
// (the distance test flags it, the rebuild names it), and leaves the list as it was: host
// positions, and device positions where the method runs on the device.
TEST_P(Lists, VerletUpdateRefusesANonFiniteCoordinate) {
  const float cutoff = 1.0f, skin = 0.3f;
  const raycut::PointCloud cloud = raycut::make_family("uniform", 300, cutoff, 3);
  std::vector<float> bad = cloud.xyz;
  bad[3 * 7 + 1] = std::numeric_limits<float>::quiet_NaN();
  std::vector<MemorySpace> spaces{MemorySpace::host};
  if (Engine(GetParam()).space() == MemorySpace::device) spaces.push_back(MemorySpace::device);
  for (const MemorySpace space : spaces) {
    std::optional<raycut::DeviceArray> good_on_device, bad_on_device;
    raycut::PositionsView good_view{cloud.xyz.data(), cloud.size(), space},
        bad_view{bad.data(), cloud.size(), space};
    if (space == MemorySpace::device) {
      good_view = good_on_device.emplace(cloud.xyz).view();
      bad_view = bad_on_device.emplace(bad).view();
    }
    raycut::VerletList verlet(GetParam(), cutoff, skin);
    ASSERT_TRUE(verlet.update(good_view));
    const raycut::NeighbourList before = verlet.list().to_host();
    try {
      verlet.update(bad_view);
      ADD_FAILURE() << "a NaN coordinate was taken";
    } catch (const raycut::Error& e) {
      EXPECT_EQ(e.code(), raycut::ErrorCode::invalid_input) << e.what();
      EXPECT_NE(std::string(e.what()).find("index 7"), std::string::npos) << e.what();
    }
    EXPECT_EQ(verlet.rebuilds(), 1u);
    EXPECT_TRUE(raycut::compare_neighbours(verlet.list().to_host(), before).equal());
    EXPECT_FALSE(verlet.update(good_view));  // nothing moved since the one build
  }
}

// An untimed engine (set_timed(false): its builds do not wait for the GPU to time themselves)
// lists what a timed one lists, open and periodic, after build() and update(), and reports no
// build times.
TEST_P(Lists, UntimedBuildsListTheSamePairs) {
  raycut::PointCloud cloud = raycut::make_family("uniform", 800, 1.0f, 4);
  const raycut::PositionsView x{cloud.xyz.data(), cloud.size(), MemorySpace::host};
  raycut::Box box;  // periodic along a and b of a 4 x 4 cell, the cloud inside it
  box.cell[0][0] = 4;
  box.cell[1][1] = 4;
  box.pbc[0] = box.pbc[1] = true;
  for (const bool periodic : {false, true}) {
    Engine timed(GetParam()), untimed(GetParam());
    untimed.set_timed(false);
    try {
      for (Engine* e : {&timed, &untimed}) {
        if (periodic)
          e->build(x, 1.0f, box);
        else
          e->build(x, 1.0f);
      }
    } catch (const raycut::Error& e) {
      if (periodic && e.code() == raycut::ErrorCode::unsupported) continue;  // OptiX, grid-paper
      throw;
    }
    const raycut::ListOptions options{false, false, false, periodic};
    EXPECT_GE(timed.last_timings().build_ms, 0);
    EXPECT_LT(untimed.last_timings().build_ms, 0);
    EXPECT_LT(untimed.last_timings().device_build_ms, 0);
    auto diff = raycut::compare_neighbours(untimed.neighbours(options), timed.neighbours(options));
    EXPECT_TRUE(diff.equal()) << "periodic " << periodic << ": " << diff.first_difference;
    for (float& v : cloud.xyz) v = std::fmod(v + 0.05f, 4.0f);
    timed.update(x);
    untimed.update(x);
    EXPECT_LT(untimed.last_timings().build_ms, 0);
    diff = raycut::compare_neighbours(untimed.neighbours(options), timed.neighbours(options));
    EXPECT_TRUE(diff.equal()) << "periodic " << periodic
                              << " after update: " << diff.first_difference;
  }
}

TEST_P(Lists, FailedRunLeavesNoResults) {
  const raycut::PointCloud cloud = raycut::make_family("uniform", 500, 1.0f, 5);
  Engine engine(GetParam());
  engine.build({cloud.xyz.data(), cloud.size(), MemorySpace::host}, 1.0f);
  engine.run(Kernel::count);
  EXPECT_THROW(engine.run(Kernel::sph_force), raycut::Error);  // no SPH inputs
  EXPECT_THROW(engine.results(), raycut::Error);
  EXPECT_THROW(engine.results_view(), raycut::Error);
}

// ListOptions::coo: the same entries as the CSR list, row by row in the same order, as int64
// (i, j), with the same distances, vectors and shifts; no uint32 indices.
TEST_P(Lists, CooListIsTheCsrListExpanded) {
  const raycut::PointCloud cloud = raycut::make_family("uniform", 700, 1.0f, 8);
  const std::size_t n = cloud.size();
  Engine engine(GetParam());
  const raycut::PositionsView x{cloud.xyz.data(), n, MemorySpace::host};
  raycut::Box box;  // periodic along a and b of a 4 x 4 cell, the cloud inside it
  box.cell[0][0] = 4;
  box.cell[1][0] = 0.5;
  box.cell[1][1] = 4;
  box.pbc[0] = box.pbc[1] = true;
  for (const bool periodic : {false, true}) {
    try {
      if (periodic)
        engine.build(x, 1.0f, box);
      else
        engine.build(x, 1.0f);
    } catch (const raycut::Error& e) {
      if (periodic && e.code() == raycut::ErrorCode::unsupported) continue;  // OptiX, grid-paper
      throw;
    }
    for (const bool half : {false, true}) {
      const raycut::ListOptions csr{half, true, true, periodic};
      raycut::ListOptions coo = csr;
      coo.coo = true;
      const raycut::NeighbourList a = engine.neighbours(csr), b = engine.neighbours(coo);
      ASSERT_EQ(b.offsets, a.offsets);
      EXPECT_TRUE(b.indices.empty());
      ASSERT_EQ(b.rows.size(), a.indices.size());
      ASSERT_EQ(b.columns.size(), a.indices.size());
      ASSERT_EQ(b.shifts.size(), a.shifts.size());
      // Row by row as sets of (j, S, |r|, r): the order within a row is not part of the contract.
      using Entry = std::tuple<std::int64_t, std::int32_t, std::int32_t, std::int32_t, float, float,
                               float, float>;
      const auto entry = [&](const raycut::NeighbourList& l, std::uint64_t e, std::int64_t j) {
        const auto s = [&](int a) { return periodic ? l.shifts[3 * e + a] : 0; };
        return Entry{j,
                     s(0),
                     s(1),
                     s(2),
                     l.distances[e],
                     l.vectors[3 * e],
                     l.vectors[3 * e + 1],
                     l.vectors[3 * e + 2]};
      };
      for (std::size_t i = 0; i < n; ++i) {
        std::vector<Entry> want, got;
        for (std::uint64_t e = a.offsets[i]; e < a.offsets[i + 1]; ++e) {
          ASSERT_EQ(b.rows[e], static_cast<std::int64_t>(i)) << "entry " << e;
          want.push_back(entry(a, e, a.indices[e]));
          got.push_back(entry(b, e, b.columns[e]));
        }
        std::sort(want.begin(), want.end());
        std::sort(got.begin(), got.end());
        ASSERT_EQ(got, want) << "row " << i << (half ? ", half" : "")
                             << (periodic ? ", periodic" : "");
      }
      EXPECT_GT(a.indices.size(), n);  // the test sees pairs
    }
  }
}

// Taken results keep their values whatever the engine runs next, and leave the engine without
// results until its next run.
TEST_P(Lists, TakenResultsOutliveLaterRuns) {
  const raycut::PointCloud cloud = raycut::make_family("uniform", 500, 1.0f, 6);
  const std::size_t n = cloud.size();
  Engine engine(GetParam());
  engine.build({cloud.xyz.data(), n, MemorySpace::host}, 1.0f);
  engine.run(Kernel::count);
  const raycut::Results want = engine.results();
  raycut::OwnedResults taken = engine.take_results();
  ASSERT_NE(taken.owner, nullptr);
  EXPECT_EQ(taken.view.space, engine.space());
  EXPECT_THROW(engine.results(), raycut::Error);
  EXPECT_THROW(engine.take_results(), raycut::Error);
  raycut::KernelOptions lj;
  lj.lj_sigma = 0.2f;
  engine.run(Kernel::lj_forces, lj);  // new arrays: the taken counts stay as they were
  engine.build({cloud.xyz.data(), n, MemorySpace::host}, 0.5f);
  engine.run(Kernel::count);
  std::vector<std::uint32_t> count(n);
  if (taken.view.space == MemorySpace::host) {
    std::copy(taken.view.count, taken.view.count + n, count.begin());
  } else {
#if defined(RAYCUT_TESTS_CUDA)
    raycut::detail::cuda::download(count.data(), taken.view.count, n * sizeof(std::uint32_t));
#else
    FAIL() << "a device method without CUDA";
#endif
  }
  EXPECT_EQ(count, want.count);
  EXPECT_NE(engine.results().count, want.count);  // the later run did change the engine's
}

INSTANTIATE_TEST_SUITE_P(Methods, Lists, ::testing::ValuesIn(available_methods()),
                         [](const auto& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

// Without a GPU, device memory is refused as unsupported, with a message saying so (it said
// "CUDA driver version is insufficient ... at src/cuda/runtime.cu:25").
TEST(Engine, DeviceMemoryWithoutAGpuIsUnsupported) {
  if (raycut::cuda_device_available()) GTEST_SKIP() << "a CUDA device is present";
  try {
    raycut::DeviceArray array(std::vector<float>{1, 2, 3});
    FAIL() << "no error";
  } catch (const raycut::Error& e) {
    EXPECT_EQ(e.code(), raycut::ErrorCode::unsupported) << e.what();
    EXPECT_NE(std::string(e.what()).find("device"), std::string::npos) << e.what();
  }
}

TEST(Engine, MovedFromThrowsInsteadOfCrashing) {
  Engine a("brute-force");
  Engine b(std::move(a));
  const float xyz[3] = {0, 0, 0};
  EXPECT_THROW(a.build({xyz, 1, MemorySpace::host}, 1.0f),
               raycut::Error);  // NOLINT(bugprone-use-after-move)
  EXPECT_THROW(a.neighbours(), raycut::Error);
  EXPECT_THROW((void)a.space(), raycut::Error);
  EXPECT_THROW(a.set_update_policy({}), raycut::Error);
  EXPECT_THROW(a.run(Kernel::count), raycut::Error);
  b.build({xyz, 1, MemorySpace::host}, 1.0f);
  EXPECT_EQ(b.compute(Kernel::count).count, std::vector<std::uint32_t>{0});
}

}  // namespace

// compare_neighbours with shifts: the same source through another image is another entry.
TEST(Compare, ShiftsAreCompared) {
  raycut::NeighbourList want;
  want.offsets = {0, 2, 2};
  want.indices = {0, 1};
  want.shifts = {1, 0, 0, 0, 0, -1};
  raycut::NeighbourList got = want;
  EXPECT_TRUE(raycut::compare_neighbours(got, want).equal());
  std::swap(got.indices[0], got.indices[1]);  // row order is free: entries move with shifts
  std::swap(got.shifts[0], got.shifts[3]);
  std::swap(got.shifts[2], got.shifts[5]);
  EXPECT_TRUE(raycut::compare_neighbours(got, want).equal());
  got = want;
  got.shifts[5] = 1;  // (1, S = (0, 0, 1)) instead of (0, 0, -1)
  const auto diff = raycut::compare_neighbours(got, want);
  EXPECT_FALSE(diff.equal());
  EXPECT_EQ(diff.differing_targets, 1u);
  EXPECT_NE(diff.first_difference.find("missing 1(0,0,-1)"), std::string::npos)
      << diff.first_difference;
  got.shifts.clear();  // a list without the shifts the oracle has cannot match
  EXPECT_FALSE(raycut::compare_neighbours(got, want).equal());
  want.shifts.clear();  // without shifts on either side: indices only, as before
  EXPECT_TRUE(raycut::compare_neighbours(got, want).equal());
}
