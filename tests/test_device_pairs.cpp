// The stream-ordered small-system pair list (raycut/device_pairs.hpp) against the double oracle
// of tests/periodic_oracle.hpp on every input family (open, cubic with several images per pair,
// triclinic, partially periodic, unwrapped by a thousand boxes, boxes 10^4 and 10^6 times the
// cutoff, float64, batches with a cell per system, half lists), and the contract around it:
// static capacity short by one, the fixed order, bad device data, and a CUDA graph captured in
// global mode (which fails on any synchronisation) replayed 1,000 steps bit for bit.
#include <cuda_runtime.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "cuda/device_pairs_host.hpp"
#include "periodic_oracle.hpp"
#include "raycut/box.hpp"
#include "raycut/device_pairs.hpp"
#include "raycut/engine.hpp"
#include "raycut/error.hpp"
#include "raycut/tools/generators.hpp"

namespace {

using raycut::Box;

#define CUDA_OK(call) ASSERT_EQ((call), cudaSuccess) << #call

bool have_gpu() {
  return raycut::cuda_device_available();
}

// Device copies of host vectors, freed at scope end.
struct DeviceVector {
  void* p = nullptr;
  std::size_t bytes = 0;
  template <class T>
  explicit DeviceVector(const std::vector<T>& v) : bytes(v.size() * sizeof(T)) {
    if (cudaMalloc(&p, bytes ? bytes : 1) != cudaSuccess) throw std::runtime_error("cudaMalloc");
    if (bytes) cudaMemcpy(p, v.data(), bytes, cudaMemcpyHostToDevice);
    // A pageable copy may return before its DMA ends; tests use the data on non-blocking streams.
    cudaDeviceSynchronize();
  }
  ~DeviceVector() { cudaFree(p); }
  DeviceVector(const DeviceVector&) = delete;
  DeviceVector& operator=(const DeviceVector&) = delete;
};

template <class T>
std::vector<T> to_host(const T* device, std::size_t count) {
  std::vector<T> v(count);
  if (count) cudaMemcpy(v.data(), device, count * sizeof(T), cudaMemcpyDeviceToHost);
  return v;
}

struct HostPairs {
  std::int64_t count = 0;
  std::vector<std::int64_t> i, j;
  std::vector<std::int32_t> shifts;
};

// Where a test runs the pass: on the GPU, or its enumeration on the host
// (detail::list_pairs_small_systems_on_host: the same arithmetic, order and codes), which
// machines without a GPU run.
// and how a row finds its sources (every particle of its system, or the cells around it: the
// same pairs, in an order of their own).
enum class Place { host, device };
struct Where {
  Place place = Place::device;
  raycut::SourceSearch search = raycut::SourceSearch::all_pairs;
};

std::string name_of(const Where& w) {
  return std::string(w.place == Place::host ? "host" : "device") +
         (w.search == raycut::SourceSearch::cells ? "_cells" : "_all_pairs");
}

void PrintTo(const Where& w, std::ostream* os) {
  *os << name_of(w);
}

bool available(const Where& where) {
  return where.place == Place::host || have_gpu();
}

const auto every_where = ::testing::Values(Where{Place::host, raycut::SourceSearch::all_pairs},
                                           Where{Place::host, raycut::SourceSearch::cells},
                                           Where{Place::device, raycut::SourceSearch::all_pairs},
                                           Where{Place::device, raycut::SourceSearch::cells});

// The boxes as the pass takes them: (B, 3, 3) cells in Real and (B, 3) pbc flags.
template <class Real>
void flatten_boxes(const std::vector<Box>& boxes, std::vector<Real>& cells,
                   std::vector<std::uint8_t>& pbc) {
  for (const Box& b : boxes)
    for (int r = 0; r < 3; ++r) {
      pbc.push_back(b.pbc[r]);
      for (int k = 0; k < 3; ++k) cells.push_back(static_cast<Real>(b.cell[r][k]));
    }
}

// The pass over one batch: positions (Real), per-system boxes, batch values. The count as
// written (negative codes included), the pairs and a few padding entries past them.
template <class Real>
HostPairs run_pass(const std::vector<Real>& xyz, const std::vector<Box>& boxes,
                   const std::vector<std::int64_t>& batch, double cutoff, bool half,
                   std::size_t capacity, Where where = {}) {
  const std::size_t n = xyz.size() / 3;
  std::vector<Real> cells;
  std::vector<std::uint8_t> pbc;
  flatten_boxes(boxes, cells, pbc);
  raycut::DeviceSystems s;
  s.scalar = sizeof(Real) == 8 ? raycut::Scalar::float64 : raycut::Scalar::float32;
  s.size = n;
  auto describe = [&](const void* x, const void* c, const void* p, const void* b) {
    s.positions = x;
    if (!boxes.empty()) {
      s.cells = c;
      s.cell_count = boxes.size();
      s.pbc = static_cast<const bool*>(p);
      s.pbc_count = boxes.size();
    }
    s.batch = batch.empty() ? nullptr : static_cast<const std::int64_t*>(b);
  };
  HostPairs out;
  const raycut::PairOptions options{half, where.search};
  if (where.place == Place::host) {
    describe(xyz.data(), cells.data(), pbc.data(), batch.data());
    out.i.resize(capacity);
    out.j.resize(capacity);
    out.shifts.resize(3 * capacity);
    raycut::StaticPairs to{out.i.data(), out.j.data(), out.shifts.data(),
                           &out.count,   capacity,     std::int64_t(n)};
    raycut::detail::list_pairs_small_systems_on_host(s, cutoff, options, to);
    return out;
  }
  DeviceVector d_xyz(xyz), d_cells(cells), d_pbc(pbc), d_batch(batch);
  describe(d_xyz.p, d_cells.p, d_pbc.p, d_batch.p);
  raycut::Context ctx;
  raycut::StaticPairBuffer buffer(capacity, ctx);
  raycut::list_pairs_small_systems(ctx, s, cutoff, options, buffer.view(std::int64_t(n)));
  out.count = to_host(buffer.count(), 1)[0];
  const std::size_t copied =
      std::min(capacity, std::size_t(std::max<std::int64_t>(out.count, 0)) + 8);
  out.i = to_host(buffer.i(), copied);
  out.j = to_host(buffer.j(), copied);
  out.shifts = to_host(buffer.shifts(), 3 * copied);
  return out;
}

// Every system of the batch against its own oracle, with the band of exactness: 1e-6 relative.
template <class Real>
void expect_exact(const std::vector<Real>& xyz, const std::vector<Box>& boxes,
                  const std::vector<std::int64_t>& batch, double cutoff, bool half,
                  const char* family, Where where) {
  SCOPED_TRACE(family);
  const std::size_t n = xyz.size() / 3;
  const HostPairs all = run_pass(xyz, boxes, batch, cutoff, half, 1 << 20, where);
  ASSERT_GE(all.count, 0);
  ASSERT_LE(all.count, 1 << 20);
  std::size_t first = 0, listed = 0;
  const std::size_t systems = batch.empty() ? 1 : std::size_t(batch.back()) + 1;
  for (std::size_t s = 0; s < systems; ++s) {
    std::size_t last = first;
    while (last < n && (batch.empty() || batch[last] == std::int64_t(s))) ++last;
    const Box box = boxes.empty() ? Box{} : boxes[boxes.size() == 1 ? 0 : s];
    std::vector<Real> local(xyz.begin() + 3 * first, xyz.begin() + 3 * last);
    const auto oracle = raycut_test::make_periodic_oracle<Real>(local, box, cutoff, 1e-6);
    std::vector<std::int64_t> i, j;
    std::vector<std::int32_t> shifts;
    for (std::int64_t p = 0; p < all.count; ++p)
      if (all.i[p] >= std::int64_t(first) && all.i[p] < std::int64_t(last)) {
        EXPECT_GE(all.j[p], std::int64_t(first)) << "a pair crosses systems";
        EXPECT_LT(all.j[p], std::int64_t(last)) << "a pair crosses systems";
        i.push_back(all.i[p] - std::int64_t(first));
        j.push_back(all.j[p] - std::int64_t(first));
        shifts.insert(shifts.end(), &all.shifts[3 * p], &all.shifts[3 * p + 3]);
      }
    listed += i.size();
    const auto check = raycut_test::check_periodic_pairs(oracle, i, j, shifts, half);
    EXPECT_TRUE(check.ok) << "system " << s << ":\n" << check.problems;
    first = last;
  }
  EXPECT_EQ(listed, std::size_t(all.count));
  // Padding past the count.
  for (std::size_t p = std::size_t(all.count); p < std::size_t(all.count) + 4; ++p) {
    EXPECT_EQ(all.i[p], std::int64_t(n));
    EXPECT_EQ(all.j[p], std::int64_t(n));
    EXPECT_EQ(all.shifts[3 * p], 0);
  }
}

std::vector<float> uniform(std::size_t n, double low, double high, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(low, high);
  std::vector<float> xyz(3 * n);
  for (float& v : xyz) v = static_cast<float>(u(rng));
  return xyz;
}

Box cubic(double l) {
  Box b;
  for (int a = 0; a < 3; ++a) {
    b.cell[a][a] = l;
    b.pbc[a] = true;
  }
  return b;
}

// A periodic triclinic cell, rows (ax, 0, 0), (bx, by, 0), (cx, cy, cz).
Box triclinic(double ax, double bx, double by, double cx, double cy, double cz) {
  Box b;
  b.cell[0][0] = ax;
  b.cell[1][0] = bx;
  b.cell[1][1] = by;
  b.cell[2][0] = cx;
  b.cell[2][1] = cy;
  b.cell[2][2] = cz;
  b.pbc[0] = b.pbc[1] = b.pbc[2] = true;
  return b;
}

class DevicePairsOn : public ::testing::TestWithParam<Where> {};

TEST_P(DevicePairsOn, EveryFamilyAgainstTheDoubleOracle) {
  const Where where = GetParam();
  if (!available(where)) GTEST_SKIP() << "no CUDA device";
  for (bool half : {false, true}) {
    SCOPED_TRACE(half ? "half" : "full");
    expect_exact(uniform(300, 0, 6, 1), {}, {}, 1.2, half, "open", where);
    // L < 2C: a pair has several images.
    expect_exact(uniform(128, 0, 5.3, 2), {cubic(5.3)}, {}, 2.5, half, "cubic, several images",
                 where);
    expect_exact(uniform(150, 0, 5, 3), {triclinic(6, 2.5, 5, -1.5, 1, 4.5)}, {}, 2.2, half,
                 "triclinic", where);
    Box slab = cubic(5);
    slab.pbc[2] = false;
    slab.cell[2][2] = 0;  // an open row may be anything, even zero
    expect_exact(uniform(120, 0, 5, 4), {slab}, {}, 1.9, half, "slab (pbc T T F)", where);
    Box wire = cubic(4);
    wire.pbc[1] = wire.pbc[2] = false;
    expect_exact(uniform(100, 0, 4, 5), {wire}, {}, 1.7, half, "wire (pbc T F F)", where);
    // Unwrapped by up to a thousand boxes.
    std::vector<float> far = uniform(100, 0, 5, 6);
    std::mt19937 rng(7);
    std::uniform_int_distribution<int> boxes(-1000, 1000);
    for (float& v : far) v += 5.0f * boxes(rng);
    expect_exact(far, {cubic(5)}, {}, 1.5, half, "unwrapped by 1000 boxes", where);
    // Boxes far larger than the cutoff: 10^4 and 10^6 cutoffs wide, particles clustered near the
    // faces so that pairs cross them.
    for (double ratio : {1e4, 1e6}) {
      const double l = ratio * 1.0;
      std::vector<float> xyz = uniform(200, 0, 3, 8);
      for (std::size_t k = 0; k < xyz.size(); k += 2) xyz[k] = static_cast<float>(l - xyz[k]);
      expect_exact(xyz, {cubic(l)}, {}, 1.0, half, ratio < 1e5 ? "L/C 1e4" : "L/C 1e6", where);
    }
    // float64 positions and cell.
    std::mt19937 rng64(9);
    std::uniform_real_distribution<double> u(0, 4.7);
    std::vector<double> xyz64(3 * 90);
    for (double& v : xyz64) v = u(rng64);
    expect_exact(xyz64, {cubic(4.7)}, {}, 1.6, half, "float64", where);
    // A batch: systems of 0..40 particles, each with its own cell and pbc (an empty one too).
    std::vector<float> batch_xyz;
    std::vector<std::int64_t> batch;
    std::vector<Box> cells;
    const int sizes[] = {12, 1, 0, 40, 25, 3};
    for (int s = 0; s < 6; ++s) {
      Box b = cubic(3.0 + 0.4 * s);
      b.pbc[s % 3] = s % 2 == 0;  // systems 1, 3 and 5 open along one axis each
      cells.push_back(b);
      const std::vector<float> part = uniform(sizes[s], 0, 3.0 + 0.4 * s, 10 + s);
      batch_xyz.insert(batch_xyz.end(), part.begin(), part.end());
      batch.insert(batch.end(), sizes[s], s);
    }
    expect_exact(batch_xyz, cells, batch, 1.4, half, "batch with a cell per system", where);
  }
}

// Systems large enough for several cells a side (the families above mostly fit one): periodic,
// triclinic, a slab (its open axis cut by its extent), an open cloud, a batch of three boxes,
// and unwrapped float64, each against the oracle; with cells, a row's pairs then come cell by
// cell, which shows that the cells were used.
TEST_P(DevicePairsOn, LargerSystemsAgainstTheDoubleOracle) {
  const Where where = GetParam();
  if (!available(where)) GTEST_SKIP() << "no CUDA device";
  for (bool half : {false, true}) {
    SCOPED_TRACE(half ? "half" : "full");
    expect_exact(uniform(1200, 0, 15, 40), {cubic(15)}, {}, 2.5, half, "cube, 6 cells a side",
                 where);
    expect_exact(uniform(1000, 0, 13, 41), {triclinic(14, 3, 13, -2, 2, 12)}, {}, 2.2, half,
                 "triclinic", where);
    Box slab = cubic(14);
    slab.pbc[2] = false;
    std::vector<float> slab_xyz = uniform(800, 0, 14, 42);
    for (std::size_t k = 2; k < slab_xyz.size(); k += 3) slab_xyz[k] *= 6.0f / 14.0f;
    expect_exact(slab_xyz, {slab}, {}, 2.0, half, "slab", where);
    expect_exact(uniform(1000, -6, 6, 43), {}, {}, 1.5, half, "open cloud", where);
    // Past 2,048 rows a row gets a warp's lanes: 69 rounds of 32 sources, past the 32 that the
    // one launch's hit masks hold; a box thinner than twice the cutoff along x, so that some
    // sources have two images, and positions unwrapped past it.
    expect_exact(uniform(2200, 0, 9, 48), {triclinic(4.6, 0, 8, 0, 0, 9)}, {}, 2.3, half,
                 "2,200 rows, 69 rounds a row", where);
    std::vector<float> batch_xyz;
    std::vector<std::int64_t> batch;
    std::vector<Box> boxes;
    for (int s = 0; s < 3; ++s) {
      const double l = 10.0 + s;
      const std::vector<float> part = uniform(400, 0, l, 44 + s);
      batch_xyz.insert(batch_xyz.end(), part.begin(), part.end());
      batch.insert(batch.end(), 400, s);
      boxes.push_back(cubic(l));
    }
    expect_exact(batch_xyz, boxes, batch, 2.5, half, "batch of three boxes", where);
    std::mt19937 rng(45);
    std::uniform_real_distribution<double> u(0, 12);
    std::uniform_int_distribution<int> wraps(-1000, 1000);
    std::vector<double> far(3 * 800);
    for (double& v : far) v = u(rng) + 12.0 * wraps(rng);
    expect_exact(far, {cubic(12)}, {}, 2.0, half, "float64 unwrapped by 1000 boxes", where);
  }
  const HostPairs cube =
      run_pass(uniform(1200, 0, 15, 40), {cubic(15)}, {}, 2.5, false, 1 << 20, where);
  bool ascending = true;
  for (std::int64_t p = 1; p < cube.count; ++p)
    if (cube.i[p] == cube.i[p - 1] && cube.j[p] < cube.j[p - 1]) ascending = false;
  EXPECT_EQ(ascending, where.search == raycut::SourceSearch::all_pairs)
      << "all pairs list j ascending in a row; cells, cell by cell";
}

// Boxes about twice the cutoff thick, where the pass switches between one image per source
// (every periodic axis thicker than 2C, less a slack) and the range of images: just above 2C
// (one image), within the slack above it and just below it (the range: a pair half a box apart
// then has two images within the cutoff). Pairs are placed half a box apart along each axis, and
// a float64 set lies 2 x 10^8 boxes out, past the single image's largest |f|.
TEST_P(DevicePairsOn, BoxesAboutTwiceTheCutoffOnEachSideOfTheSingleImage) {
  const Where where = GetParam();
  if (!available(where)) GTEST_SKIP() << "no CUDA device";
  const double cutoff = 1.0;
  for (double side : {2.0 * (1 + 1e-3), 2.0 * (1 + 1e-7), 2.0 * (1 - 1e-3)}) {
    std::vector<float> xyz = uniform(200, 0, side, 60);
    for (int a = 0; a < 3; ++a) {  // pairs half a box apart along axis a
      float p[3] = {0.1f, 0.2f, 0.3f};
      xyz.insert(xyz.end(), p, p + 3);
      p[a] += static_cast<float>(side / 2);
      xyz.insert(xyz.end(), p, p + 3);
    }
    for (bool half : {false, true}) {
      SCOPED_TRACE(half ? "half" : "full");
      expect_exact(xyz, {cubic(side)}, {}, cutoff, half, "cube about 2C", where);
      expect_exact(xyz, {triclinic(side, 0.3, side, -0.2, 0.1, side)}, {}, cutoff, half,
                   "triclinic about 2C", where);
    }
  }
  std::mt19937 rng(61);
  std::uniform_real_distribution<double> u(0, 6);
  std::vector<double> far(3 * 300);
  for (double& v : far) v = u(rng) + 6.0 * 2e8;
  expect_exact(far, {cubic(6)}, {}, 2.0, false, "float64 2e8 boxes out", where);
}

// Odd inputs through both searches: a NaN position and an unsorted batch give their codes, never
// a wrong list; coincident particles (an extent of zero), a far outlier (every other particle
// in one cell of a grid a million cutoffs wide) and coordinates near 10^30 give the oracle's
// pairs.
TEST_P(DevicePairsOn, OddInputsGiveTheirCodesOrTheOraclesPairs) {
  const Where where = GetParam();
  if (!available(where)) GTEST_SKIP() << "no CUDA device";
  std::vector<float> with_nan = uniform(3000, 0, 15, 50);
  with_nan[3 * 1234 + 1] = std::numeric_limits<float>::quiet_NaN();
  EXPECT_EQ(run_pass(with_nan, {cubic(15)}, {}, 2.5, false, 1 << 20, where).count,
            raycut::count_non_finite_position);
  std::vector<std::int64_t> unsorted(3000, 0);
  std::fill(unsorted.begin() + 1500, unsorted.end(), 1);
  unsorted[700] = 1;
  EXPECT_EQ(run_pass(uniform(3000, 0, 15, 51), {cubic(15), cubic(15)}, unsorted, 2.5, false,
                     1 << 20, where)
                .count,
            raycut::count_unsorted_batch);
  const std::vector<float> coincident(3 * 600, 2.5f);
  expect_exact(coincident, {}, {}, 1.0, false, "coincident", where);
  expect_exact(coincident, {cubic(7)}, {}, 1.0, true, "coincident, periodic", where);
  std::vector<float> outlier = uniform(700, 0, 10, 52);
  outlier.insert(outlier.end(), {1e6f, 1e6f, 1e6f});
  expect_exact(outlier, {}, {}, 1.5, false, "a far outlier", where);
  std::vector<float> huge = uniform(300, 0, 1, 53);
  for (float& v : huge) v = 1e30f * (1 + v);
  expect_exact(huge, {}, {}, 1.0, false, "coordinates near 10^30", where);
}

TEST_P(DevicePairsOn, CapacityShortByOneIsReportedAndTheRestIsExact) {
  const Where where = GetParam();
  if (!available(where)) GTEST_SKIP() << "no CUDA device";
  const std::vector<float> xyz = uniform(128, 0, 5.3, 11);
  const HostPairs exact = run_pass(xyz, {cubic(5.3)}, {}, 2.5, false, 1 << 16, where);
  ASSERT_GT(exact.count, 1);
  const auto short_by_one = std::size_t(exact.count - 1);
  const HostPairs cut = run_pass(xyz, {cubic(5.3)}, {}, 2.5, false, short_by_one, where);
  EXPECT_EQ(cut.count, exact.count) << "the true count, above the capacity";
  for (std::size_t p = 0; p < short_by_one; ++p) {
    ASSERT_EQ(cut.i[p], exact.i[p]) << p;
    ASSERT_EQ(cut.j[p], exact.j[p]) << p;
    ASSERT_EQ(cut.shifts[3 * p + 2], exact.shifts[3 * p + 2]) << p;
  }
  if (where.place == Place::host) return;
  // The growing helper starts from nothing and ends with every pair.
  DeviceVector d_xyz(xyz);
  std::vector<double> cell = {5.3, 0, 0, 0, 5.3, 0, 0, 0, 5.3};
  std::vector<float> cellf(cell.begin(), cell.end());
  DeviceVector d_cell(cellf);
  raycut::DeviceSystems s;
  s.positions = d_xyz.p;
  s.size = 128;
  s.cells = d_cell.p;
  s.cell_count = 1;
  raycut::Context ctx;
  raycut::StaticPairBuffer grown;
  EXPECT_EQ(raycut::list_pairs_small_systems_growing(ctx, s, 2.5, {}, grown), exact.count);
  EXPECT_GE(grown.capacity(), std::size_t(exact.count));
  EXPECT_EQ(to_host(grown.j(), exact.count),
            std::vector<std::int64_t>(exact.j.begin(), exact.j.begin() + exact.count));
}

// The pass with a list of k slots per system (StaticPairs::systems), on the host or the GPU:
// every slot and each system's count.
struct PerSystemLists {
  std::vector<std::int64_t> i, j, count;
  std::vector<std::int32_t> shifts;
};
PerSystemLists run_per_system(const std::vector<float>& xyz, const std::vector<Box>& boxes,
                              const std::vector<std::int64_t>& batch, double cutoff, std::size_t k,
                              const Where& where) {
  const std::size_t systems = boxes.size(), n = batch.size();
  std::vector<float> cells;
  std::vector<std::uint8_t> pbc;
  flatten_boxes(boxes, cells, pbc);
  PerSystemLists got{
      std::vector<std::int64_t>(systems * k, -9), std::vector<std::int64_t>(systems * k, -9),
      std::vector<std::int64_t>(systems, -9), std::vector<std::int32_t>(3 * systems * k, -9)};
  raycut::DeviceSystems sys;
  sys.size = n;
  sys.cell_count = sys.pbc_count = systems;
  const raycut::PairOptions options{false, where.search};
  raycut::StaticPairs out{got.i.data(),   got.j.data(), got.shifts.data(), got.count.data(), k,
                          std::int64_t(n)};
  out.systems = systems;
  if (where.place == Place::host) {
    sys.positions = xyz.data();
    sys.cells = cells.data();
    sys.pbc = reinterpret_cast<const bool*>(pbc.data());
    sys.batch = batch.data();
    raycut::detail::list_pairs_small_systems_on_host(sys, cutoff, options, out);
    return got;
  }
  DeviceVector d_xyz(xyz), d_cells(cells), d_pbc(pbc), d_batch(batch), d_i(got.i), d_j(got.j),
      d_count(got.count), d_shifts(got.shifts);
  sys.positions = d_xyz.p;
  sys.cells = d_cells.p;
  sys.pbc = static_cast<const bool*>(d_pbc.p);
  sys.batch = static_cast<const std::int64_t*>(d_batch.p);
  out.i = static_cast<std::int64_t*>(d_i.p);
  out.j = static_cast<std::int64_t*>(d_j.p);
  out.shifts = static_cast<std::int32_t*>(d_shifts.p);
  out.count = static_cast<std::int64_t*>(d_count.p);
  raycut::list_pairs_small_systems(raycut::Context{}, sys, cutoff, options, out);
  EXPECT_EQ(cudaDeviceSynchronize(), cudaSuccess);
  got.i = to_host(out.i, systems * k);
  got.j = to_host(out.j, systems * k);
  got.shifts = to_host(out.shifts, 3 * systems * k);
  got.count = to_host(out.count, systems);
  return got;
}

// A list per system (StaticPairs::systems, what jax.vmap maps onto): each system's K slots hold
// exactly what a pass over that system alone gives (global indices), with its own count, also
// when another system overflows its slots; an empty system is all padding.
TEST_P(DevicePairsOn, AListPerSystemEqualsAPassPerSystem) {
  const Where where = GetParam();
  if (!available(where)) GTEST_SKIP() << "no CUDA device";
  const std::vector<std::size_t> sizes = {40, 0, 90, 25};
  std::vector<float> xyz;
  std::vector<std::int64_t> batch;
  std::vector<Box> boxes;
  for (std::size_t s = 0; s < sizes.size(); ++s) {
    const std::vector<float> part = uniform(sizes[s], 0, 4.0, 30 + int(s));
    xyz.insert(xyz.end(), part.begin(), part.end());
    batch.insert(batch.end(), sizes[s], std::int64_t(s));
    boxes.push_back(cubic(4.0 + 0.5 * double(s)));
  }
  const std::size_t systems = sizes.size(), k = 400, n = batch.size();
  const double cutoff = 1.6;
  // The reference: each system alone, indices made global.
  std::vector<HostPairs> alone(systems);
  std::size_t first = 0;
  for (std::size_t s = 0; s < systems; ++s) {
    const std::vector<float> part(xyz.begin() + 3 * first, xyz.begin() + 3 * (first + sizes[s]));
    alone[s] = run_pass(part, {boxes[s]}, {}, cutoff, false, 1 << 14, {Place::host, where.search});
    for (auto& v : {&alone[s].i, &alone[s].j})
      for (std::int64_t& x : *v) x += std::int64_t(first);
    first += sizes[s];
  }
  ASSERT_GT(alone[2].count, std::int64_t(k)) << "system 2 overflows its slots";
  ASSERT_LT(alone[0].count, std::int64_t(k));
  const PerSystemLists got = run_per_system(xyz, boxes, batch, cutoff, k, where);
  for (std::size_t s = 0; s < systems; ++s) {
    EXPECT_EQ(got.count[s], alone[s].count) << "system " << s;
    const std::size_t kept = std::min<std::size_t>(k, std::size_t(alone[s].count));
    for (std::size_t e = 0; e < k; ++e) {
      const std::size_t at = s * k + e;
      const std::int64_t want_i = e < kept ? alone[s].i[e] : std::int64_t(n);
      const std::int64_t want_j = e < kept ? alone[s].j[e] : std::int64_t(n);
      ASSERT_EQ(got.i[at], want_i) << "system " << s << ", slot " << e;
      ASSERT_EQ(got.j[at], want_j) << "system " << s << ", slot " << e;
      for (int c = 0; c < 3; ++c)
        ASSERT_EQ(got.shifts[3 * at + c], e < kept ? alone[s].shifts[3 * e + c] : 0)
            << "system " << s << ", slot " << e;
    }
  }
}

// A batch of `systems` small systems of 0 to 110 particles each (mean 55), each in its own box
// 3.6 to 6.5 wide: cubes, triclinic cells and slabs (pbc T T F), several images per pair in the
// thinner ones at the cutoff used below.
struct ManySystems {
  std::vector<float> xyz;
  std::vector<std::int64_t> batch;
  std::vector<Box> boxes;
};
ManySystems many_small_systems(std::size_t systems, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> size(0, 110);
  std::uniform_real_distribution<double> width(3.6, 6.5);
  ManySystems out;
  for (std::size_t s = 0; s < systems; ++s) {
    const double l = width(rng);
    Box b = s % 3 == 1 ? triclinic(l, 0.3 * l, 0.9 * l, -0.2 * l, 0.1 * l, l) : cubic(l);
    if (s % 3 == 2) b.pbc[2] = false;
    out.boxes.push_back(b);
    const auto n = static_cast<std::size_t>(size(rng));
    const std::vector<float> part = uniform(n, 0, l, seed + 1 + unsigned(s));
    out.xyz.insert(out.xyz.end(), part.begin(), part.end());
    out.batch.insert(out.batch.end(), n, std::int64_t(s));
  }
  return out;
}

// Batches with more rows than a block per row takes, where the one-launch pass gives each row a
// warp (about 3,900 rows), 16 lanes (18,700) or 8 (37,400), and its tiles of 1, 2 or 4 rows find
// their offsets by the look-back: every system against the oracle, full and half; the capacity
// short by one; and a list per system equal to the one list cut by system.
TEST_P(DevicePairsOn, ManySmallSystemsAgainstTheDoubleOracle) {
  const Where where = GetParam();
  if (!available(where)) GTEST_SKIP() << "no CUDA device";
  const double cutoff = 1.8;
  for (std::size_t systems : {70, 340, 680}) {
    SCOPED_TRACE(std::to_string(systems) + " systems");
    const ManySystems b = many_small_systems(systems, 100 + unsigned(systems));
    const std::size_t n = b.batch.size();
    for (bool half : {false, true})
      expect_exact(b.xyz, b.boxes, b.batch, cutoff, half, "many small systems", where);
    const HostPairs exact = run_pass(b.xyz, b.boxes, b.batch, cutoff, false, 1 << 20, where);
    ASSERT_GT(exact.count, 1);
    const auto short_by_one = std::size_t(exact.count - 1);
    const HostPairs cut = run_pass(b.xyz, b.boxes, b.batch, cutoff, false, short_by_one, where);
    EXPECT_EQ(cut.count, exact.count) << "the true count, above the capacity";
    for (std::size_t p = 0; p < std::min(short_by_one, cut.i.size()); ++p) {
      ASSERT_EQ(cut.i[p], exact.i[p]) << p;
      ASSERT_EQ(cut.j[p], exact.j[p]) << p;
    }
    // A list per system of k slots, k the median system's count: half the systems overflow.
    std::vector<std::int64_t> per_system(systems, 0);
    for (std::int64_t p = 0; p < exact.count; ++p) ++per_system[std::size_t(b.batch[exact.i[p]])];
    std::vector<std::int64_t> sorted_counts = per_system;
    std::nth_element(sorted_counts.begin(), sorted_counts.begin() + systems / 2,
                     sorted_counts.end());
    const auto k = static_cast<std::size_t>(sorted_counts[systems / 2]);
    ASSERT_GT(k, 0u);
    const PerSystemLists got = run_per_system(b.xyz, b.boxes, b.batch, cutoff, k, where);
    std::vector<std::size_t> next(systems, 0);  // the next slot of each system
    for (std::int64_t p = 0; p < exact.count; ++p) {
      const auto s = std::size_t(b.batch[exact.i[p]]);
      const std::size_t e = next[s]++;
      if (e >= k) continue;
      const std::size_t at = s * k + e;
      ASSERT_EQ(got.i[at], exact.i[p]) << "system " << s << ", slot " << e;
      ASSERT_EQ(got.j[at], exact.j[p]) << "system " << s << ", slot " << e;
      for (int c = 0; c < 3; ++c)
        ASSERT_EQ(got.shifts[3 * at + c], exact.shifts[3 * p + c])
            << "system " << s << ", slot " << e;
    }
    for (std::size_t s = 0; s < systems; ++s) {
      EXPECT_EQ(got.count[s], per_system[s]) << "system " << s;
      for (std::size_t e = std::min<std::size_t>(k, next[s]); e < k; ++e)
        ASSERT_EQ(got.i[s * k + e], std::int64_t(n)) << "padding of system " << s << ", slot " << e;
    }
  }
}

TEST_P(DevicePairsOn, BadDataGivesItsCountCodeAndOnlyPadding) {
  const Where where = GetParam();
  if (!available(where)) GTEST_SKIP() << "no CUDA device";
  std::vector<float> xyz = uniform(50, 0, 3, 12);
  xyz[3 * 17 + 1] = std::numeric_limits<float>::quiet_NaN();
  const HostPairs nan = run_pass(xyz, {}, {}, 1.0, false, 100, where);
  EXPECT_EQ(nan.count, raycut::count_non_finite_position);
  EXPECT_EQ(nan.i[0], 50) << "bad input: every entry is padding";
  std::vector<std::int64_t> unsorted(50, 0);
  unsorted[10] = 1;  // 0 .. 0 1 0 .. 0
  EXPECT_EQ(run_pass(uniform(50, 0, 3, 13), {}, unsorted, 1.0, false, 100, where).count,
            raycut::count_unsorted_batch);
  Box flat = cubic(3);
  flat.cell[2][0] = 3;  // row c = row a: dependent
  flat.cell[2][2] = 0;
  EXPECT_EQ(run_pass(uniform(50, 0, 3, 14), {flat}, {}, 1.0, false, 100, where).count,
            raycut::count_invalid_cell);
  std::vector<std::int64_t> beyond(50, 0);
  beyond[49] = 3;  // two cells for systems 0 and 1, a particle in system 3
  EXPECT_EQ(
      run_pass(uniform(50, 0, 3, 15), {cubic(3), cubic(3)}, beyond, 1.0, false, 100, where).count,
      raycut::count_batch_out_of_range);
  std::vector<std::int64_t> negative(50, 0);
  negative[0] = -1;  // sorted, but not a system: refused without cells too, as the Engine does
  EXPECT_EQ(run_pass(uniform(50, 0, 3, 15), {}, negative, 1.0, false, 100, where).count,
            raycut::count_batch_out_of_range);
  // A cell 300 times thinner than the cutoff on each axis: ~6e2^3 images per pair, refused.
  EXPECT_EQ(run_pass(uniform(4, 0, 0.01, 17), {cubic(0.01)}, {}, 3.0, false, 100, where).count,
            raycut::count_too_many_images);
  // An infinite coordinate in a periodic cell: its code, in the time of any other pass (the
  // other rows' image range towards it is not finite: no images, not 2^31 of them).
  for (float infinity :
       {std::numeric_limits<float>::infinity(), -std::numeric_limits<float>::infinity()}) {
    std::vector<float> far = uniform(50, 0, 3, 16);
    far[3 * 20] = infinity;
    const HostPairs inf = run_pass(far, {cubic(3)}, {}, 1.0, false, 100, where);
    EXPECT_EQ(inf.count, raycut::count_non_finite_position) << infinity;
    EXPECT_EQ(inf.i[0], 50) << "bad input: every entry is padding";
  }
}

TEST(DevicePairs, ReadPairCountNamesBadDataAndHostArgumentsFailEarly) {
  if (!have_gpu()) GTEST_SKIP() << "no CUDA device";
  std::vector<float> xyz = uniform(50, 0, 3, 12);
  xyz[3 * 17 + 1] = std::numeric_limits<float>::quiet_NaN();
  DeviceVector d_xyz(xyz);
  raycut::DeviceSystems s;
  s.positions = d_xyz.p;
  s.size = 50;
  raycut::Context ctx;
  raycut::StaticPairBuffer pairs(100, ctx);
  raycut::list_pairs_small_systems(ctx, s, 1.0, {}, pairs.view(50));
  try {
    raycut::read_pair_count(ctx, pairs.count());
    FAIL() << "NaN accepted";
  } catch (const raycut::Error& e) {
    EXPECT_EQ(e.code(), raycut::ErrorCode::invalid_input);
    EXPECT_NE(std::string(e.what()).find("NaN"), std::string::npos) << e.what();
  }
  // Host-side arguments throw before any work.
  raycut::DeviceSystems none;
  raycut::StaticPairBuffer buffer(4, ctx);
  EXPECT_THROW(raycut::list_pairs_small_systems(ctx, none, 0.0, {}, buffer.view(0)), raycut::Error);
  none.size = 3;  // positions null
  EXPECT_THROW(raycut::list_pairs_small_systems(ctx, none, 1.0, {}, buffer.view(0)), raycut::Error);
}

// The policy's crossover, as measured (device_pairs.hpp): the sizes each side of it.
TEST(DevicePairs, SmallSystemPolicyFollowsThePairTests) {
  EXPECT_TRUE(raycut::prefer_small_systems(1000, 1));
  EXPECT_TRUE(raycut::prefer_small_systems(4096, 1));
  EXPECT_FALSE(raycut::prefer_small_systems(4097, 1));
  EXPECT_FALSE(raycut::prefer_small_systems(10000, 1));
  EXPECT_TRUE(raycut::prefer_small_systems(32 * 100, 32));
  EXPECT_TRUE(raycut::prefer_small_systems(256 * 100, 256));
  EXPECT_TRUE(raycut::prefer_small_systems(512 * 128, 512));
  EXPECT_FALSE(raycut::prefer_small_systems(512 * 128 + 1, 512));
  EXPECT_FALSE(raycut::prefer_small_systems(64 * 4096, 64));
  EXPECT_FALSE(raycut::prefer_small_systems(10, 0));
  EXPECT_TRUE(raycut::prefer_small_systems(0, 1));
  // No overflow at sizes past 2^32 particles.
  EXPECT_FALSE(raycut::prefer_small_systems(std::size_t(1) << 40, std::size_t(1) << 20));
}

TEST(DevicePairs, HostArgumentsAreCheckedBeforeAnyWork) {
  raycut::DeviceSystems none;
  std::int64_t i[4], j[4], count = 7;
  const raycut::StaticPairs out{i, j, nullptr, &count, 4, 0};
  for (double cutoff : {0.0, -1.0, std::numeric_limits<double>::infinity(), 1e-50})
    EXPECT_THROW(raycut::detail::list_pairs_small_systems_on_host(none, cutoff, {}, out),
                 raycut::Error)
        << cutoff;
  none.size = 3;  // positions null
  EXPECT_THROW(raycut::detail::list_pairs_small_systems_on_host(none, 1.0, {}, out), raycut::Error);
  none.positions = i;
  raycut::StaticPairs no_count = out;
  no_count.count = nullptr;
  EXPECT_THROW(raycut::detail::list_pairs_small_systems_on_host(none, 1.0, {}, no_count),
               raycut::Error);
  EXPECT_EQ(count, 7) << "nothing written";
}

// Capacities whose byte sizes would wrap around are refused, naming the capacity, before any
// allocation or work (so this runs without a GPU).
TEST(DevicePairs, CapacitiesPastTheLargestAreRefused) {
  const raycut::Context ctx;
  for (std::size_t capacity : {(std::size_t(1) << 56) + 1, std::size_t(1) << 61, ~std::size_t(0)}) {
    try {
      raycut::StaticPairBuffer buffer(capacity, ctx);
      ADD_FAILURE() << "capacity " << capacity << " accepted";
    } catch (const raycut::Error& e) {
      EXPECT_EQ(e.code(), raycut::ErrorCode::invalid_argument) << e.what();
      EXPECT_NE(std::string(e.what()).find(std::to_string(capacity)), std::string::npos)
          << e.what();
    }
  }
  raycut::DeviceSystems none;
  std::int64_t i[1], j[1], count = 7;
  const raycut::StaticPairs huge{i, j, nullptr, &count, (std::size_t(1) << 56) + 1, 0};
  EXPECT_THROW(raycut::detail::list_pairs_small_systems_on_host(none, 1.0, {}, huge),
               raycut::Error);
  EXPECT_EQ(count, 7) << "nothing written";
}

// Pairs within an ulp of the cutoff, chosen so that a fused multiply-add in |r|^2 (the device's
// default contraction, in either order of the first two terms) would decide them the other way:
// the device must decide each as its host mirror does, bit for bit. Two float64 particles per
// system, x_i = 0 and x_j = r, in one open batch; cutoff 1, so cutoff^2 = 1 exactly.
std::vector<double> pairs_at_the_cutoff(std::size_t wanted) {
  std::mt19937_64 rng(31);
  std::normal_distribution<double> gauss(0, 1);
  std::vector<double> xyz;
  while (xyz.size() < 6 * wanted) {
    double r[3] = {gauss(rng), gauss(rng), gauss(rng)};
    const double length = std::sqrt(r[0] * r[0] + r[1] * r[1] + r[2] * r[2]);
    for (double& c : r) c /= length;
    for (int step = 0; step < 8; ++step) {  // walk r[2] by ulps across |r| = 1
      const double plain = r[0] * r[0] + r[1] * r[1] + r[2] * r[2];
      const double fused_a = std::fma(r[2], r[2], std::fma(r[1], r[1], r[0] * r[0]));
      const double fused_b = std::fma(r[2], r[2], std::fma(r[0], r[0], r[1] * r[1]));
      if ((plain < 1) != (fused_a < 1) && (plain < 1) != (fused_b < 1)) {
        xyz.insert(xyz.end(), {0.0, 0.0, 0.0, r[0], r[1], r[2]});
        break;
      }
      r[2] = std::nextafter(r[2], plain < 1 ? 2.0 : 0.0);
    }
  }
  return xyz;
}

TEST_P(DevicePairsOn, PairsAtTheCutoffAreDecidedAsOnTheHost) {
  const Where where = GetParam();
  if (!available(where)) GTEST_SKIP() << "no CUDA device";
  constexpr std::size_t systems = 400;
  const std::vector<double> xyz = pairs_at_the_cutoff(systems);
  std::vector<std::int64_t> batch;
  for (std::size_t s = 0; s < systems; ++s) batch.insert(batch.end(), 2, std::int64_t(s));
  // The host mirror's decision, without FMA contraction (this file too: -ffp-contract=off).
  std::vector<std::int64_t> i, j;
  for (std::size_t s = 0; s < systems; ++s) {
    const double* r = &xyz[6 * s + 3];
    if (r[0] * r[0] + r[1] * r[1] + r[2] * r[2] < 1) {
      i.insert(i.end(), {std::int64_t(2 * s), std::int64_t(2 * s + 1)});
      j.insert(j.end(), {std::int64_t(2 * s + 1), std::int64_t(2 * s)});
    }
  }
  ASSERT_GT(i.size(), 0u);
  ASSERT_LT(i.size(), 2 * systems) << "both decisions are represented";
  const HostPairs found = run_pass(xyz, {}, batch, 1.0, false, 2 * systems, where);
  ASSERT_EQ(found.count, std::int64_t(i.size()));
  EXPECT_EQ(std::vector<std::int64_t>(found.i.begin(), found.i.begin() + found.count), i);
  EXPECT_EQ(std::vector<std::int64_t>(found.j.begin(), found.j.begin() + found.count), j);
}

INSTANTIATE_TEST_SUITE_P(Where, DevicePairsOn, every_where,
                         [](const auto& info) { return name_of(info.param); });

// A step (positions copied in, the pass) captured in global mode, replayed 1,000 times over new
// positions, against the eager pass on the same positions, bit for bit.
TEST(DevicePairs, GraphCaptureReplaysBitForBit) {
  if (!have_gpu()) GTEST_SKIP() << "no CUDA device";
  constexpr std::size_t n = 100, capacity = 4000;
  cudaStream_t stream;
  CUDA_OK(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking));
  raycut::Context ctx{stream, nullptr};
  std::vector<float> cellf = {4.9f, 0, 0, 0, 4.9f, 0, 0, 0, 4.9f};
  DeviceVector d_cell(cellf), staging(std::vector<float>(3 * n)), work(std::vector<float>(3 * n));
  raycut::DeviceSystems s;
  s.positions = work.p;
  s.size = n;
  s.cells = d_cell.p;
  s.cell_count = 1;
  raycut::StaticPairBuffer replayed(capacity, ctx), eager(capacity, ctx);

  cudaGraph_t graph;
  CUDA_OK(cudaStreamBeginCapture(stream, cudaStreamCaptureModeGlobal));
  CUDA_OK(
      cudaMemcpyAsync(work.p, staging.p, 3 * n * sizeof(float), cudaMemcpyDeviceToDevice, stream));
  raycut::list_pairs_small_systems(ctx, s, 2.0, {}, replayed.view(n));
  CUDA_OK(cudaStreamEndCapture(stream, &graph));
  cudaGraphExec_t exec;
  CUDA_OK(cudaGraphInstantiate(&exec, graph, 0));

  std::vector<float> xyz = uniform(n, 0, 4.9, 15);
  std::mt19937 rng(16);
  std::normal_distribution<float> kick(0, 0.05f);
  for (int step = 0; step < 1000; ++step) {
    for (float& v : xyz) v += kick(rng);
    CUDA_OK(cudaMemcpyAsync(staging.p, xyz.data(), 3 * n * sizeof(float), cudaMemcpyHostToDevice,
                            stream));
    CUDA_OK(cudaGraphLaunch(exec, stream));
    raycut::list_pairs_small_systems(ctx, s, 2.0, {}, eager.view(n));
    const std::int64_t count = raycut::read_pair_count(ctx, eager.count());
    ASSERT_LE(count, std::int64_t(capacity));
    ASSERT_EQ(raycut::read_pair_count(ctx, replayed.count()), count) << "step " << step;
    if (step % 100 == 0 || step == 999) {
      ASSERT_EQ(to_host(replayed.i(), capacity), to_host(eager.i(), capacity)) << step;
      ASSERT_EQ(to_host(replayed.j(), capacity), to_host(eager.j(), capacity)) << step;
      ASSERT_EQ(to_host(replayed.shifts(), 3 * capacity), to_host(eager.shifts(), 3 * capacity));
    }
  }
  cudaGraphExecDestroy(exec);
  cudaGraphDestroy(graph);
  replayed = {};
  eager = {};
  cudaStreamSynchronize(stream);
  cudaStreamDestroy(stream);
}

}  // namespace

namespace {

// A Verlet step captured in global mode: the displacement check, the rebuild only when needed,
// the copy of the reference positions. Replayed over 300 steps of moving particles, the list
// always holds every pair within the cutoff, and rebuilds happen some steps and not others.
TEST(DevicePairs, VerletStepInAGraphRebuildsOnlyWhenNeeded) {
  if (!have_gpu()) GTEST_SKIP() << "no CUDA device";
  constexpr std::size_t n = 128;
  constexpr double cutoff = 2.0, skin = 0.4;
  cudaStream_t stream;
  CUDA_OK(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking));
  raycut::Context ctx{stream, nullptr};
  std::vector<float> cellf = {5.3f, 0, 0, 0, 5.3f, 0, 0, 0, 5.3f};
  std::vector<float> xyz = uniform(n, 0, 5.3, 21);
  DeviceVector d_cell(cellf), work(xyz);
  raycut::DeviceSystems s;
  s.positions = work.p;
  s.size = n;
  s.cells = d_cell.p;
  s.cell_count = 1;
  {
    raycut::DeviceVerletList verlet(ctx, cutoff, skin, 20000);
    verlet.update(s);  // the first update rebuilds, outside the graph
    cudaGraph_t graph;
    CUDA_OK(cudaStreamBeginCapture(stream, cudaStreamCaptureModeGlobal));
    verlet.update(s);
    CUDA_OK(cudaStreamEndCapture(stream, &graph));
    cudaGraphExec_t exec;
    CUDA_OK(cudaGraphInstantiate(&exec, graph, 0));
    std::mt19937 rng(22);
    std::normal_distribution<float> kick(0, 0.02f);
    int rebuilds = 0, steps = 300;
    for (int step = 0; step < steps; ++step) {
      for (float& v : xyz) v += kick(rng);
      CUDA_OK(cudaMemcpyAsync(work.p, xyz.data(), xyz.size() * sizeof(float),
                              cudaMemcpyHostToDevice, stream));
      CUDA_OK(cudaGraphLaunch(exec, stream));
      const std::int64_t count = raycut::read_pair_count(ctx, verlet.pairs().count());
      ASSERT_LE(count, 20000);
      rebuilds += to_host(verlet.rebuilt(), 1)[0];
      // Every pair within the cutoff now is in the list (the list is a superset).
      const auto oracle = raycut_test::make_periodic_oracle<float>(xyz, cubic(5.3), cutoff, 1e-6);
      const auto i = to_host(verlet.pairs().i(), std::size_t(count));
      const auto j = to_host(verlet.pairs().j(), std::size_t(count));
      const auto sh = to_host(verlet.pairs().shifts(), 3 * std::size_t(count));
      std::vector<raycut_test::PeriodicTriple> listed;
      for (std::int64_t p = 0; p < count; ++p)
        listed.push_back({i[p], j[p], sh[3 * p], sh[3 * p + 1], sh[3 * p + 2]});
      std::sort(listed.begin(), listed.end());
      for (const auto& t : oracle.in)
        ASSERT_TRUE(std::binary_search(listed.begin(), listed.end(), t))
            << "step " << step << ": missing " << raycut_test::triple_text(t);
    }
    EXPECT_GT(rebuilds, 0) << "the particles moved far enough to rebuild";
    EXPECT_LT(rebuilds, steps / 2) << "a skin of " << skin << " should spare most rebuilds";
    cudaGraphExecDestroy(exec);
    cudaGraphDestroy(graph);
  }
  cudaStreamSynchronize(stream);
  cudaStreamDestroy(stream);
}

}  // namespace

namespace {

// The conformance families (raycut::family_names(), docs/methods.md "Test inputs"): open
// systems of 0 to 900 particles, through the small-system path with static capacity, against
// the double oracle; then the same with the capacity one short of the count.
class DevicePairsFamilies : public ::testing::TestWithParam<std::tuple<std::string, Where>> {};

TEST_P(DevicePairsFamilies, StaticCapacityMatchesTheOracle) {
  const auto& [family, where] = GetParam();
  if (!available(where)) GTEST_SKIP() << "no CUDA device";
  for (std::size_t n : {0, 1, 2, 300, 900}) {  // coincident: n^2 pairs, within the capacity
    SCOPED_TRACE(family + " n=" + std::to_string(n));
    const raycut::PointCloud cloud = raycut::make_family(family, n, 1.0f, 42 + n);
    for (bool half : {false, true})
      expect_exact(cloud.xyz, {}, {}, cloud.cutoff, half, family.c_str(), where);
    const HostPairs exact = run_pass(cloud.xyz, {}, {}, cloud.cutoff, false, 1 << 20, where);
    if (exact.count < 1) continue;
    const HostPairs cut =
        run_pass(cloud.xyz, {}, {}, cloud.cutoff, false, std::size_t(exact.count - 1), where);
    EXPECT_EQ(cut.count, exact.count) << "overflow by one is reported with the true count";
  }
}

std::vector<std::string> unscaled_families() {
  std::vector<std::string> out;
  for (const auto& family : raycut::family_names())  // tiny-/huge-scale rescale their cutoff
    if (raycut::make_family(family, 1, 1.0f, 0).cutoff == 1.0f) out.push_back(family);
  return out;
}

INSTANTIATE_TEST_SUITE_P(Families, DevicePairsFamilies,
                         ::testing::Combine(::testing::ValuesIn(unscaled_families()), every_where),
                         [](const auto& info) {
                           std::string name =
                               std::get<0>(info.param) + "_" + name_of(std::get<1>(info.param));
                           for (char& ch : name)
                             if (!std::isalnum(static_cast<unsigned char>(ch))) ch = '_';
                           return name;
                         });

}  // namespace
