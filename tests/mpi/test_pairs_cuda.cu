// raycut::mpi::cuda::for_each_pair (nvcc): a caller's functor on the GPU traversal of a
// device-resident DistributedEngine against the same functor through raycut::mpi::for_each_pair
// on a host-resident cell-list engine over the same particles, by global index and exactly:
// neighbour counts, sums of the neighbours' global ids (device_ids()) and of their global shifts,
// a per-source field through the device halo_fields(), and accepts() by global index. Both the
// local-axes and the all-axes scheme (halos to itself at one rank). Part of raycut_mpi_tests
// (its main), so it runs at 1 to 4 ranks; skipped without a GPU.
#include <cuda_runtime.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "mpi/ranks.hpp"
#include "raycut/engine.hpp"
#include "raycut/mpi/distributed.hpp"
#include "raycut/mpi/pairs.cuh"
#include "raycut/tools/device_array.hpp"

namespace {

using raycut::Box;
using raycut::MemorySpace;
using raycut::Shift;
using raycut::Vec3;
using raycut::mpi::DistributedEngine;
using raycut::mpi::DistributedOptions;

// Per owned target: in-range neighbours whose global id is not a multiple of 7, the sum of their
// ids, of their shifts (weighted per axis) and of their charges (small integers: exact sums).
struct Census {
  struct Accumulator {
    std::uint32_t count = 0;
    unsigned long long ids = 0;
    long long shifts = 0;
    double charge = 0;
  };
  using options = raycut::functor_options<raycut::option::accepts>;
  std::uint32_t owned;
  const std::uint64_t* ids;       // owned, then halos' (halo_ids)
  const std::uint64_t* halo_ids;  //
  const float* charge;            // owned + halos (halo_fields)
  std::uint32_t* count;
  unsigned long long* id_sum;
  long long* shift_sum;
  double* charge_sum;

  RAYCUT_HD std::uint64_t id(std::uint32_t j) const {
    return j < owned ? ids[j] : halo_ids[j - owned];
  }
  RAYCUT_HD bool accepts(std::uint32_t, std::uint32_t j, const Shift&) const {
    return id(j) % 7 != 0;
  }
  RAYCUT_HD void operator()(Accumulator& a, std::uint32_t, std::uint32_t j, Vec3, float,
                            const Shift& s) const {
    ++a.count;
    a.ids += id(j);
    a.shifts += s.a + 3 * s.b + 9 * s.c;
    a.charge += charge[j];
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& a) const {
    count[i] = a.count;
    id_sum[i] = a.ids;
    shift_sum[i] = a.shifts;
    charge_sum[i] = a.charge;
  }
};

template <class T>
struct Device {
  T* p = nullptr;
  explicit Device(std::size_t n) {
    if (cudaMalloc(&p, (n > 0 ? n : 1) * sizeof(T)) != cudaSuccess) p = nullptr;
  }
  ~Device() { cudaFree(p); }
  std::vector<T> host(std::size_t n) const {
    std::vector<T> v(n);
    if (n > 0) cudaMemcpy(v.data(), p, n * sizeof(T), cudaMemcpyDeviceToHost);
    return v;
  }
};

struct Tally {
  std::vector<std::uint32_t> count;
  std::vector<unsigned long long> ids;
  std::vector<long long> shifts;
  std::vector<double> charge;
};

// The per-target results by global id, summed over the ranks (each id owned once).
Tally by_id(const DistributedEngine& e, const Tally& owned, std::size_t n) {
  Tally mine{std::vector<std::uint32_t>(n), std::vector<unsigned long long>(n),
             std::vector<long long>(n), std::vector<double>(n)};
  for (std::size_t t = 0; t < e.owned(); ++t) {
    const std::uint64_t id = e.ids()[t];
    mine.count[id] = owned.count[t];
    mine.ids[id] = owned.ids[t];
    mine.shifts[id] = owned.shifts[t];
    mine.charge[id] = owned.charge[t];
  }
  Tally all = mine;
  const int m = static_cast<int>(n);
  MPI_Allreduce(mine.count.data(), all.count.data(), m, MPI_UINT32_T, MPI_SUM, MPI_COMM_WORLD);
  MPI_Allreduce(mine.ids.data(), all.ids.data(), m, MPI_UNSIGNED_LONG_LONG, MPI_SUM,
                MPI_COMM_WORLD);
  MPI_Allreduce(mine.shifts.data(), all.shifts.data(), m, MPI_LONG_LONG, MPI_SUM, MPI_COMM_WORLD);
  MPI_Allreduce(mine.charge.data(), all.charge.data(), m, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  return all;
}

float charge_of(std::uint64_t id) {
  return static_cast<float>(1 + id % 5);
}

TEST(DistributedDevice, UserFunctorsOnTheGpuMatchTheHostEngine) {
  raycut::mpi::select_local_device(MPI_COMM_WORLD);
  if (!raycut::cuda_device_available()) GTEST_SKIP() << "no CUDA device";
  const std::size_t n = 3000;
  const float side = 12, cutoff = 1.5f;
  std::mt19937_64 rng(2026);
  std::uniform_real_distribution<float> u(0.0f, side);
  std::vector<float> xyz(3 * n);
  for (float& x : xyz) x = u(rng);
  // This rank's strided share.
  std::vector<float> mine;
  std::vector<std::uint64_t> ids;
  for (std::size_t i = 0; i < n; ++i) {
    if (static_cast<int>(i % world_size()) != world_rank()) continue;
    ids.push_back(i);
    mine.insert(mine.end(), &xyz[3 * i], &xyz[3 * i] + 3);
  }
  const Box box = Box::orthorhombic(side, side, side);

  for (bool local_images : {true, false}) {
    const std::string what = local_images ? "local axes" : "every axis by halos";
    DistributedOptions device_options, host_options;
    device_options.method = "grid";
    host_options.method = "cell-list";
    device_options.local_images = host_options.local_images = local_images;
    DistributedEngine device(MPI_COMM_WORLD, device_options), host(MPI_COMM_WORLD, host_options);
    const raycut::DeviceArray d_xyz(mine);
    device.build({d_xyz.data(), ids.size(), MemorySpace::device}, ids.data(), cutoff, box);
    host.build({mine.data(), ids.size(), MemorySpace::host}, ids.data(), cutoff, box);
    ASSERT_EQ(device.space(), MemorySpace::device);
    if (!local_images) ASSERT_GT(device.halos(), 0u) << what;

    // The host twin: host arrays.
    std::vector<float> q_owned;
    for (std::uint64_t id : host.ids()) q_owned.push_back(charge_of(id));
    const std::vector<float> q_local = host.halo_fields(q_owned.data(), 1);
    const std::size_t h_owned = host.owned();
    Tally want{std::vector<std::uint32_t>(h_owned), std::vector<unsigned long long>(h_owned),
               std::vector<long long>(h_owned), std::vector<double>(h_owned)};
    raycut::mpi::for_each_pair(
        host, Census{static_cast<std::uint32_t>(h_owned), host.ids().data(), host.halo_ids().data(),
                     q_local.data(), want.count.data(), want.ids.data(), want.shifts.data(),
                     want.charge.data()});

    // The device engine: device arrays, the charges' halo copies sent on the GPU.
    const std::size_t d_owned = device.owned(), local = d_owned + device.halos();
    std::vector<float> dq_owned;
    for (std::uint64_t id : device.ids()) dq_owned.push_back(charge_of(id));
    const raycut::DeviceArray dq(dq_owned);
    Device<float> dq_local(local);
    device.halo_fields(dq.data(), 1, dq_local.p);
    Device<std::uint32_t> count(d_owned);
    Device<unsigned long long> id_sum(d_owned);
    Device<long long> shift_sum(d_owned);
    Device<double> charge_sum(d_owned);
    const DistributedEngine::DeviceIds d_ids = device.device_ids();
    ASSERT_NE(d_ids.ids, nullptr);
    if (device.halos() > 0) ASSERT_NE(d_ids.halo_shifts, nullptr);
    raycut::mpi::cuda::for_each_pair(
        device, Census{static_cast<std::uint32_t>(d_owned), d_ids.ids, d_ids.halo_ids, dq_local.p,
                       count.p, id_sum.p, shift_sum.p, charge_sum.p});
    ASSERT_EQ(cudaDeviceSynchronize(), cudaSuccess) << what;
    const Tally got{count.host(d_owned), id_sum.host(d_owned), shift_sum.host(d_owned),
                    charge_sum.host(d_owned)};
    // The charges' halo copies through the device plan are the host twin's.
    EXPECT_EQ(dq_local.host(local), device.halo_fields(dq_owned.data(), 1)) << what;

    const Tally a = by_id(device, got, n), b = by_id(host, want, n);
    std::uint64_t pairs = 0;
    for (std::uint32_t c : b.count) pairs += c;
    EXPECT_GT(pairs, 10 * n) << what;  // ~24 neighbours each, a sixth refused by accepts
    EXPECT_EQ(a.count, b.count) << what;
    EXPECT_EQ(a.ids, b.ids) << what;
    EXPECT_EQ(a.shifts, b.shifts) << what;
    EXPECT_EQ(a.charge, b.charge) << what;
  }
}

TEST(DistributedDevice, UserFunctorsOnTheGpuNeedDevicePositions) {
  raycut::mpi::select_local_device(MPI_COMM_WORLD);
  if (!raycut::cuda_device_available()) GTEST_SKIP() << "no CUDA device";
  DistributedOptions options;
  options.method = "grid";
  DistributedEngine engine(MPI_COMM_WORLD, options);
  const std::vector<float> xyz = {1, 1, 1, 2, 1, 1};
  const std::vector<std::uint64_t> ids = {0, 1};
  const bool first = world_rank() == 0;
  engine.build({xyz.data(), first ? 2u : 0u, MemorySpace::host}, ids.data(), 1.5f,
               Box::orthorhombic(8, 8, 8));
  EXPECT_EQ(engine.device_ids().ids, nullptr);
  Census f{};
  try {
    raycut::mpi::cuda::for_each_pair(engine, f);
    ADD_FAILURE() << "a host-resident engine with a GPU method ran a device functor";
  } catch (const raycut::Error& e) {
    EXPECT_EQ(e.code(), raycut::ErrorCode::unsupported);
    EXPECT_NE(std::string(e.what()).find("device positions"), std::string::npos) << e.what();
  }
  float out = 0;
  try {
    engine.halo_fields(&out, 1, &out);
    ADD_FAILURE() << "device halo_fields on a host-resident engine";
  } catch (const raycut::Error& e) {
    EXPECT_EQ(e.code(), raycut::ErrorCode::unsupported);
  }
}

}  // namespace
