// Engine::neighbours into a static capacity (StaticPairs): the same pairs, in the same order, as
// the exactly sized list (each row's entries as its CSR row holds them, rows ascending), the true
// count beside them, padding after them, nothing written past the capacity; open clouds,
// periodic boxes, half lists and per-pair cutoffs, on every method (GPU methods write device
// memory through raycut::StaticPairBuffer and are skipped without a GPU).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <tuple>
#include <vector>

#include "method_availability.hpp"
#include "raycut/device_pairs.hpp"
#include "raycut/engine.hpp"
#include "raycut/tools/device_array.hpp"
#include "raycut/tools/generators.hpp"

#if defined(RAYCUT_TESTS_CUDA)
#include <cuda_runtime.h>

#include "cuda/runtime.hpp"  // copy(), read_back(): device pairs written and read back
#endif

namespace {

using raycut::Engine;
using raycut::ListOptions;
using raycut::MemorySpace;

using raycut_test::every_method;
using raycut_test::unavailable;

// A static list read back: i, j, S of every slot (capacity), the count, and whatever lies in
// the `guard` slots past the capacity (a write there is a bug).
struct Read {
  std::vector<std::int64_t> i, j;
  std::vector<std::int32_t> shifts;
  std::int64_t count = -99;
};

constexpr std::int64_t sentinel = -7;
constexpr std::size_t guard = 16;

#if defined(RAYCUT_TESTS_CUDA)
// A device static list's `slots` entries, read back after the work queued on `stream`: the count
// first (read_back waits for the stream, and reads at most 64 bytes), then the arrays, whole.
Read read_static(raycut::StaticPairBuffer& buffer, std::size_t slots, bool shifts, void* stream) {
  Read r;
  raycut::detail::cuda::read_back(&r.count, buffer.count(), 8, stream);
  r.i.resize(slots);
  r.j.resize(slots);
  raycut::detail::cuda::copy(r.i.data(), buffer.i(), slots * 8);
  raycut::detail::cuda::copy(r.j.data(), buffer.j(), slots * 8);
  if (shifts) {
    r.shifts.resize(3 * slots);
    raycut::detail::cuda::copy(r.shifts.data(), buffer.shifts(), 3 * slots * 4);
  }
  return r;
}
#endif

// Runs the static list on `engine` with `capacity`, in the method's memory, and reads it back.
Read run_static(Engine& engine, std::size_t capacity, ListOptions options, bool shifts) {
  const std::size_t slots = capacity + guard;
  Read r;
  if (engine.space() == MemorySpace::host) {
    r.i.assign(slots, sentinel);
    r.j.assign(slots, sentinel);
    r.shifts.assign(3 * slots, static_cast<std::int32_t>(sentinel));
    raycut::StaticPairs out{r.i.data(), r.j.data(), shifts ? r.shifts.data() : nullptr,
                            &r.count,   capacity,   static_cast<std::int64_t>(engine.sources())};
    engine.neighbours(out, options);
    if (!shifts) r.shifts.clear();
    return r;
  }
#if defined(RAYCUT_TESTS_CUDA)
  raycut::Context ctx;
  ctx.stream = engine.stream();
  raycut::StaticPairBuffer buffer(slots, ctx);
  // The guard slots: filled with the sentinel, and the list told of `capacity` only.
  std::vector<std::int64_t> fill(slots, sentinel);
  std::vector<std::int32_t> fill_shifts(3 * slots, static_cast<std::int32_t>(sentinel));
  raycut::detail::cuda::copy(buffer.i(), fill.data(), slots * sizeof(std::int64_t));
  raycut::detail::cuda::copy(buffer.j(), fill.data(), slots * sizeof(std::int64_t));
  raycut::detail::cuda::copy(buffer.shifts(), fill_shifts.data(), 3 * slots * 4);
  raycut::StaticPairs out = buffer.view(static_cast<std::int64_t>(engine.sources()));
  out.capacity = capacity;
  if (!shifts) out.shifts = nullptr;
  engine.neighbours(out, options);  // queued on the engine's stream: read back after it
  return read_static(buffer, slots, shifts, ctx.stream);
#else
  ADD_FAILURE() << "a device method without CUDA";
  return r;
#endif
}

// The exactly sized list's entries as COO rows: the reference order.
struct Expected {
  std::vector<std::int64_t> i, j;
  std::vector<std::int32_t> shifts;
};
Expected exact(Engine& engine, ListOptions options, bool shifts) {
  options.shifts = shifts;
  const raycut::NeighbourList list = engine.neighbours(options);
  Expected e;
  for (std::size_t row = 0; row + 1 < list.offsets.size(); ++row)
    for (std::uint64_t p = list.offsets[row]; p < list.offsets[row + 1]; ++p) {
      e.i.push_back(static_cast<std::int64_t>(row));
      e.j.push_back(list.indices[p]);
      if (shifts) e.shifts.insert(e.shifts.end(), &list.shifts[3 * p], &list.shifts[3 * p] + 3);
    }
  return e;
}

// Every slot of a static list against the exact list: the first min(count, capacity) entries
// equal, padding after them, the guard untouched, the count the exact one.
void expect_static_equals(const Read& r, const Expected& e, std::size_t capacity, std::int64_t pad,
                          const std::string& what) {
  const std::size_t total = e.i.size(), written = std::min(total, capacity);
  ASSERT_EQ(r.count, static_cast<std::int64_t>(total)) << what;
  for (std::size_t k = 0; k < capacity + guard; ++k) {
    const std::int64_t want_i = k < written ? e.i[k] : k < capacity ? pad : sentinel;
    const std::int64_t want_j = k < written ? e.j[k] : k < capacity ? pad : sentinel;
    ASSERT_EQ(r.i[k], want_i) << what << ": slot " << k << " of capacity " << capacity;
    ASSERT_EQ(r.j[k], want_j) << what << ": slot " << k << " of capacity " << capacity;
    if (r.shifts.empty()) continue;
    for (int c = 0; c < 3; ++c) {
      const std::int32_t want = k < written    ? e.shifts[3 * k + c]
                                : k < capacity ? 0
                                               : static_cast<std::int32_t>(sentinel);
      ASSERT_EQ(r.shifts[3 * k + c], want) << what << ": S of slot " << k;
    }
  }
}

class StaticLists : public ::testing::TestWithParam<std::string> {
 protected:
  void SetUp() override {
    if (const std::string why = unavailable(GetParam()); !why.empty())
      GTEST_SKIP() << GetParam() << ": " << why;
  }
  // Capacities around the count: short by one, exact, with room, and none.
  static std::vector<std::size_t> capacities(std::size_t count) {
    return {count > 0 ? count - 1 : 0, count, count + 37, 0};
  }
};

TEST_P(StaticLists, OpenCloudEqualsTheExactList) {
  const raycut::PointCloud cloud = raycut::make_family("uniform", 1500, 1.0f, 3);
  Engine engine(GetParam());
  engine.build({cloud.xyz.data(), cloud.size(), MemorySpace::host}, 1.0f);
  for (const bool half : {false, true}) {
    const ListOptions options{.half = half};
    const Expected e = exact(engine, options, false);
    ASSERT_GT(e.i.size(), 1000u);
    for (const std::size_t capacity : capacities(e.i.size()))
      expect_static_equals(run_static(engine, capacity, options, false), e, capacity,
                           static_cast<std::int64_t>(cloud.size()),
                           std::string(half ? "half" : "full") + " list");
  }
}

TEST_P(StaticLists, PeriodicBoxWithShiftsAndPerPairCutoffs) {
  if (!raycut::method_capabilities(GetParam()).periodic_boxes)
    GTEST_SKIP() << GetParam() << " takes no periodic box";
  // A triclinic box thinner than twice the cutoff: self-images and several images per pair.
  raycut::Box box;
  box.cell[0][0] = 3.0;
  box.cell[1][0] = 0.8;
  box.cell[1][1] = 2.7;
  box.cell[2][1] = -0.5;
  box.cell[2][2] = 2.4;
  box.pbc[0] = box.pbc[1] = box.pbc[2] = true;
  const raycut::PointCloud cloud = raycut::make_family("uniform", 60, 1.0f, 11);
  std::vector<float> xyz = cloud.xyz;
  for (std::size_t p = 0; p < xyz.size(); p += 3)  // spread over the box, some outside it
    for (int c = 0; c < 3; ++c) xyz[p + c] = 4.0f * xyz[p + c] - 0.5f;
  std::vector<double> radius(cloud.size());
  for (std::size_t p = 0; p < radius.size(); ++p) radius[p] = 0.35 + 0.1 * (p % 4);
  raycut::PairCutoffs cutoffs;
  cutoffs.radii = radius.data();
  Engine engine(GetParam());
  engine.build({xyz.data(), cloud.size(), MemorySpace::host}, 1.31f, box);
  for (const bool half : {false, true})
    for (const bool own : {false, true}) {
      const ListOptions options{.half = half, .cutoffs = own ? &cutoffs : nullptr};
      const Expected e = exact(engine, options, true);
      ASSERT_GT(e.i.size(), 100u);
      for (const std::size_t capacity : capacities(e.i.size()))
        expect_static_equals(
            run_static(engine, capacity, options, true), e, capacity,
            static_cast<std::int64_t>(cloud.size()),
            std::string(half ? "half" : "full") + (own ? ", per-pair cutoffs" : ""));
    }
}

TEST_P(StaticLists, EmptyBuildWritesTheCountAndPadding) {
  Engine engine(GetParam());
  const float none[3] = {0, 0, 0};
  engine.build({none, 0, MemorySpace::host}, 1.0f);
  expect_static_equals(run_static(engine, 5, {}, false), Expected{}, 5, 0, "N = 0");
}

// Engine::set_reuse_plan. The pairs of a static list as a sorted set of (i, j, S): a reused
// plan's grid may be another than a fresh one's, and visit rows' pairs in another order.
std::vector<std::tuple<std::int64_t, std::int64_t, std::int32_t, std::int32_t, std::int32_t>>
pair_set(const Read& r) {
  std::vector<std::tuple<std::int64_t, std::int64_t, std::int32_t, std::int32_t, std::int32_t>>
      pairs;
  for (std::int64_t k = 0; k < r.count; ++k)
    pairs.emplace_back(r.i[k], r.j[k], r.shifts[3 * k], r.shifts[3 * k + 1], r.shifts[3 * k + 2]);
  std::sort(pairs.begin(), pairs.end());
  return pairs;
}
std::vector<std::tuple<std::int64_t, std::int64_t, std::int32_t, std::int32_t, std::int32_t>>
pair_set(const Expected& e) {
  Read r;
  r.i = e.i;
  r.j = e.j;
  r.shifts = e.shifts;
  r.count = static_cast<std::int64_t>(e.i.size());
  return pair_set(r);
}

// A cube of side L, periodic along `periodic` of its axes, and n particles in it; moved by
// step() by up to `jump` on each axis (periodic axes unwrapped: positions leave the cube).
struct Liquid {
  raycut::Box box;
  std::vector<float> xyz;
  std::mt19937 random{7};
  Liquid(std::size_t n, double side, int periodic) {
    for (int a = 0; a < 3; ++a) {
      box.cell[a][a] = side;
      box.pbc[a] = a < periodic;
    }
    std::uniform_real_distribution<float> u(0.0f, static_cast<float>(side));
    xyz.resize(3 * n);
    for (float& v : xyz) v = u(random);
  }
  void step(float jump) {
    std::uniform_real_distribution<float> u(-jump, jump);
    for (float& v : xyz) v += u(random);
  }
};

Read static_list(Engine& engine, const raycut::DeviceArray& x, const raycut::Box& box, float cutoff,
                 std::size_t capacity) {
  engine.build(x.view(), cutoff, box);
  return run_static(engine, capacity, {}, true);
}

// A reused plan lists what a fresh build lists, step after step, periodic and partially
// periodic, while the particles move (and leave the cube: unwrapped); its exact list too.
TEST(ReusedPlans, ListTheFreshPairsStepAfterStep) {
  if (const std::string why = unavailable("grid"); !why.empty()) GTEST_SKIP() << why;
  const float cutoff = 1.0f;
  for (const int periodic : {3, 2}) {
    Liquid liquid(3000, 9.0, periodic);
    Engine fresh("grid"), reused("grid");
    reused.set_reuse_plan(true);
    for (int step = 0; step < 6; ++step) {
      const raycut::DeviceArray x(liquid.xyz);
      const Read want = static_list(fresh, x, liquid.box, cutoff, 200000);
      const Read got = static_list(reused, x, liquid.box, cutoff, 200000);
      const std::string what =
          std::to_string(periodic) + " periodic axes, step " + std::to_string(step);
      ASSERT_GT(want.count, 10000) << what;
      ASSERT_EQ(got.count, want.count) << what;
      EXPECT_EQ(pair_set(got), pair_set(want)) << what;
      EXPECT_EQ(pair_set(exact(reused, {}, true)), pair_set(want)) << what << ", exact list";
      liquid.step(0.05f);
    }
  }
}

// A batch: three periodic systems of their own boxes, one grid (each system's layer of cells,
// the spare slots parked in every layer); the reused plan lists what a fresh build lists.
TEST(ReusedPlans, ListTheFreshPairsOfABatch) {
  if (const std::string why = unavailable("grid"); !why.empty()) GTEST_SKIP() << why;
  const float cutoff = 1.0f;
  raycut::Systems systems;
  std::vector<float> xyz;
  systems.offsets = {0};
  for (const double side : {7.0, 8.0, 9.0}) {
    const Liquid one(static_cast<std::size_t>(2.5 * side * side * side), side, 3);
    systems.boxes.push_back(one.box);
    xyz.insert(xyz.end(), one.xyz.begin(), one.xyz.end());
    systems.offsets.push_back(xyz.size() / 3);
  }
  Engine fresh("grid"), reused("grid");
  reused.set_reuse_plan(true);
  std::mt19937 random{11};
  std::uniform_real_distribution<float> jump(-0.05f, 0.05f);
  for (int step = 0; step < 4; ++step) {
    const raycut::DeviceArray x(xyz);
    fresh.build(x.view(), cutoff, systems);
    const Read want = run_static(fresh, 400000, {}, true);
    reused.build(x.view(), cutoff, systems);
    const Read got = run_static(reused, 400000, {}, true);
    ASSERT_GT(want.count, 10000) << "step " << step;
    ASSERT_EQ(got.count, want.count) << "step " << step;
    EXPECT_EQ(pair_set(got), pair_set(want)) << "step " << step;
    for (float& v : xyz) v += jump(random);
  }
}

// A plan that no longer fits is reported, never used: more images than it has room for (every
// particle moved to a face), or a particle outside its grid (an open axis), give the count
// count_plan_outgrown; once that count has been read, the next build plans afresh. A list that
// waits (the exact one) builds afresh at once. A NaN gives count_non_finite_position, and the
// next build names it.
TEST(ReusedPlans, OutgrownIsReportedThenPlannedAfresh) {
  if (const std::string why = unavailable("grid"); !why.empty()) GTEST_SKIP() << why;
  const float cutoff = 1.0f;
  Liquid liquid(2000, 10.0, 2);
  for (std::size_t p = 0; p < liquid.xyz.size(); p += 3)  // away from the faces: few images
    for (int a = 0; a < 2; ++a) liquid.xyz[p + a] = 2.0f + 0.6f * liquid.xyz[p + a];
  Engine fresh("grid"), reused("grid");
  reused.set_reuse_plan(true);
  const raycut::DeviceArray start(liquid.xyz);
  ASSERT_GT(static_list(reused, start, liquid.box, cutoff, 100000).count, 0);

  std::vector<float> at_faces = liquid.xyz;  // x near 0: every particle has an image
  for (std::size_t p = 0; p < at_faces.size(); p += 3) at_faces[p] = 0.1f * at_faces[p];
  std::vector<float> outside = liquid.xyz;  // the open axis stretched twice as far
  for (std::size_t p = 0; p < outside.size(); p += 3) outside[p + 2] *= 2.0f;
  for (const auto* moved : {&at_faces, &outside}) {
    const raycut::DeviceArray x(*moved);
    const Read want = static_list(fresh, x, liquid.box, cutoff, 1000000);
    ASSERT_GT(want.count, 0);
    EXPECT_EQ(static_list(reused, x, liquid.box, cutoff, 1000000).count,
              raycut::count_plan_outgrown);
    const Read again = static_list(reused, x, liquid.box, cutoff, 1000000);  // planned afresh
    ASSERT_EQ(again.count, want.count);
    EXPECT_EQ(pair_set(again), pair_set(want));
    // A plan made for the start, then the moved positions: the exact list builds afresh.
    Engine waits("grid");
    waits.set_reuse_plan(true);
    ASSERT_GT(static_list(waits, start, liquid.box, cutoff, 1000000).count, 0);
    waits.build(x.view(), cutoff, liquid.box);
    EXPECT_EQ(pair_set(exact(waits, {}, true)), pair_set(want));
  }

  std::vector<float> bad = liquid.xyz;
  bad[3 * 5 + 1] = std::numeric_limits<float>::quiet_NaN();
  ASSERT_GT(static_list(reused, start, liquid.box, cutoff, 1000000).count, 0);
  const raycut::DeviceArray x(bad);
  EXPECT_EQ(static_list(reused, x, liquid.box, cutoff, 1000000).count,
            raycut::count_non_finite_position);
  try {
    reused.build(x.view(), cutoff, liquid.box);
    ADD_FAILURE() << "a NaN coordinate was taken";
  } catch (const raycut::Error& e) {
    EXPECT_NE(std::string(e.what()).find("particle index 5"), std::string::npos) << e.what();
  }
}

#if defined(RAYCUT_TESTS_CUDA)
// A build that reuses its plan, captured with its static list in a global-mode CUDA graph (which
// fails on any synchronisation): each replay over positions changed in place lists what a fresh
// build lists; positions the plan no longer fits give the count count_plan_outgrown at replay.
TEST(ReusedPlans, CapturedStepReplaysTheFreshPairs) {
  if (const std::string why = unavailable("grid"); !why.empty()) GTEST_SKIP() << why;
  const float cutoff = 1.0f;
  const std::size_t capacity = 200000;
  Liquid liquid(3000, 9.0, 3);
  raycut::DeviceArray x(liquid.xyz);
  // Declared first, so destroyed last: the buffer frees on it when it goes (raycut::Context).
  struct OwnedStream {
    cudaStream_t stream = nullptr;
    OwnedStream() { cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking); }
    ~OwnedStream() {
      cudaStreamSynchronize(stream);
      cudaStreamDestroy(stream);
    }
  } owned;
  cudaStream_t stream = owned.stream;
  ASSERT_NE(stream, nullptr);
  Engine fresh("grid"), reused("grid");
  reused.set_stream(stream);
  reused.set_timed(false);
  reused.set_reuse_plan(true);
  raycut::Context ctx;
  ctx.stream = stream;
  raycut::StaticPairBuffer buffer(capacity, ctx);
  const raycut::StaticPairs out = buffer.view(static_cast<std::int64_t>(liquid.xyz.size() / 3));
  const auto step = [&] {
    reused.build(x.view(), cutoff, liquid.box);
    reused.neighbours(out, {});
  };
  step();  // plans and records
  step();  // reuses
  cudaGraph_t graph = nullptr;
  ASSERT_EQ(cudaStreamBeginCapture(stream, cudaStreamCaptureModeGlobal), cudaSuccess);
  step();
  ASSERT_EQ(cudaStreamEndCapture(stream, &graph), cudaSuccess);
  cudaGraphExec_t exec = nullptr;
  ASSERT_EQ(cudaGraphInstantiate(&exec, graph, 0), cudaSuccess);
  const auto replay = [&] {
    raycut::detail::cuda::copy(x.data(), liquid.xyz.data(), liquid.xyz.size() * sizeof(float));
    EXPECT_EQ(cudaDeviceSynchronize(), cudaSuccess);  // the copy has landed
    EXPECT_EQ(cudaGraphLaunch(exec, stream), cudaSuccess);
    return read_static(buffer, capacity, true, stream);
  };
  for (int s = 0; s < 5; ++s) {
    liquid.step(0.05f);
    const raycut::DeviceArray now(liquid.xyz);
    const Read want = static_list(fresh, now, liquid.box, cutoff, capacity);
    const Read got = replay();
    ASSERT_GT(want.count, 10000) << "step " << s;
    ASSERT_EQ(got.count, want.count) << "step " << s;
    EXPECT_EQ(pair_set(got), pair_set(want)) << "step " << s;
  }
  for (std::size_t p = 0; p < liquid.xyz.size(); p += 3) liquid.xyz[p] *= 0.1f;  // all at a face
  EXPECT_EQ(replay().count, raycut::count_plan_outgrown);
  cudaGraphExecDestroy(exec);
  cudaGraphDestroy(graph);
}
#endif

INSTANTIATE_TEST_SUITE_P(Methods, StaticLists, ::testing::ValuesIn(every_method()),
                         [](const auto& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

TEST(StaticListsRefusals, NameWhatIsWrong) {
  const std::vector<float> xyz = {0, 0, 0, 0.5f, 0, 0};
  Engine engine("cell-list");
  engine.build({xyz.data(), 2, MemorySpace::host}, 1.0f);
  std::vector<std::int64_t> i(4), j(4);
  std::int64_t count = 0;
  const raycut::StaticPairs out{i.data(), j.data(), nullptr, &count, 4, 2};
  const auto message = [&](const raycut::StaticPairs& o, const ListOptions& options) {
    try {
      engine.neighbours(o, options);
    } catch (const raycut::Error& e) {
      EXPECT_EQ(e.code(), raycut::ErrorCode::invalid_argument);
      return std::string(e.what());
    }
    return std::string("accepted");
  };
  EXPECT_NE(message(out, {.distances = true}).find("distances, vectors and coo are not options"),
            std::string::npos);
  raycut::StaticPairs no_count = out;
  no_count.count = nullptr;
  EXPECT_NE(message(no_count, {}).find("needs its count, and its i and j arrays"),
            std::string::npos);
  raycut::StaticPairs none{nullptr, nullptr, nullptr, &count, 0, 2};
  EXPECT_EQ(message(none, {}), "accepted");  // capacity 0: the count only
  EXPECT_EQ(count, 2);
  raycut::StaticPairs no_i = out;
  no_i.i = nullptr;
  EXPECT_NE(message(no_i, {}).find("unless the capacity is 0"), std::string::npos);
  EXPECT_EQ(message(out, {}), "accepted");
  EXPECT_EQ(count, 2);
  EXPECT_EQ(i, (std::vector<std::int64_t>{0, 1, 2, 2}));
  EXPECT_EQ(j, (std::vector<std::int64_t>{1, 0, 2, 2}));
}

}  // namespace
