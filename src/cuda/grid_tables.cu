#include <thrust/iterator/counting_iterator.h>
#include <cub/block/block_scan.cuh>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <cub/device/device_select.cuh>
#include <cuda/functional>

#include <algorithm>
#include <cstdint>

#include "cuda/grid_tables.cuh"
#include "cuda/scan.cuh"
#include "raycut/detail/cuda/grid_pass.cuh"
#include "raycut/static_pairs.hpp"

namespace raycut::detail::cuda {
namespace {

constexpr int one_block_threads = 1024;

__device__ __forceinline__ void watch_point(const PlannedBox& watch, float x, float y, float z) {
  if (watch.misfit && !(x >= watch.lo[0] && x <= watch.hi[0] && y >= watch.lo[1] &&
                        y <= watch.hi[1] && z >= watch.lo[2] && z <= watch.hi[2]))
    atomicCAS(watch.misfit, 0, static_cast<int>(count_plan_outgrown));
}

// Point i's cell key (and the planned box watched).
__device__ __forceinline__ std::uint64_t watched_key(const float* __restrict__ xyz, Slot i,
                                                     const GridGeometry& view,
                                                     const PlannedBox& watch) {
  const float x = xyz[3 * i], y = xyz[3 * i + 1], z = xyz[3 * i + 2];
  watch_point(watch, x, y, z);
  return cell_key(view, x, y, z, i);
}

template <class Key>
__global__ void keys_kernel(const float* __restrict__ xyz, Slot n, GridGeometry view,
                            PlannedBox watch, Key* keys, Slot* index) {
  const Slot i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  keys[i] = static_cast<Key>(watched_key(xyz, i, view, watch));
  index[i] = i;
}

// Particle i as the compute reads it: a float4 with w = i.
__device__ __forceinline__ float4 particle(const float* __restrict__ xyz, Slot i) {
  return make_float4(xyz[3 * std::size_t{i}], xyz[3 * std::size_t{i} + 1],
                     xyz[3 * std::size_t{i} + 2], __uint_as_float(i));
}

__device__ __forceinline__ void gather_one(const float* __restrict__ xyz, const Slot* order, Slot s,
                                           float4* pos) {
  pos[s] = particle(xyz, order[s]);
}

// Counting sort, pass 1 for particle i: its cell key, counted in start[] by an atomic whose
// return value is a provisional rank within the cell (its order varies from run to run).
__device__ __forceinline__ void count_one(const float* __restrict__ xyz, Slot i,
                                          const GridGeometry& view, const PlannedBox& watch,
                                          std::uint32_t* keys, Slot* provisional, Slot* start) {
  const auto key = static_cast<std::uint32_t>(watched_key(xyz, i, view, watch));
  keys[i] = key;
  provisional[i] = atomicAdd(&start[key], 1u);
}

// Counting sort, pass 4 for particle i of the cell whose particles are members[first, last): its
// slot is first plus the number of them with a smaller index, exactly the layout of a stable sort
// by cell, so every sum is the same from run to run. order[slot] = i, as a radix sort leaves it.
__device__ __forceinline__ void place_one(const float* __restrict__ xyz, const Slot* members,
                                          Slot first, Slot last, Slot i, float4* pos, Slot* order) {
  Slot rank = 0;
  for (Slot s = first; s < last; ++s) rank += members[s] < i;
  pos[first + rank] = particle(xyz, i);
  order[first + rank] = i;
}

// Dense, after a radix sort: the end of each cell's run, at entry key + 1 of start[] (zeroed,
// cells + 1 entries), and the gather. A prefix maximum then gives start[c] = the number of
// particles in cells below c, empty cells included: no search, no atomics.
__global__ void run_ends_kernel(const float* __restrict__ xyz, const std::uint32_t* keys,
                                const Slot* order, Slot n, Slot* start, float4* pos) {
  const Slot s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= n) return;
  if (s + 1 == n || keys[s] != keys[s + 1]) start[keys[s] + 1] = s + 1;
  gather_one(xyz, order, s, pos);
}

// Dense, counting sort. Pass 1: each particle's cell, counted in start[] (zeroed, cells + 1
// entries); pass 4 removes the order of the atomics.
__global__ void count_cells_kernel(const float* __restrict__ xyz, Slot n, GridGeometry view,
                                   PlannedBox watch, std::uint32_t* keys, Slot* provisional,
                                   Slot* start) {
  const Slot i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) count_one(xyz, i, view, watch, keys, provisional, start);
}

// Dense, small inputs: the counting sort of passes 1 to 4 (count_cells_kernel .. place_kernel) in
// one block, one launch instead of six: launches, not work, are the cost of small inputs
// (docs/grid.md). The scan gives each thread a run of consecutive cells.
__global__ void __launch_bounds__(one_block_threads)
    small_dense_build_kernel(const float* __restrict__ xyz, Slot n, GridGeometry view,
                             PlannedBox watch, std::uint32_t cells, std::uint32_t* keys,
                             Slot* provisional, Slot* members, Slot* start, float4* pos) {
  using Scan = cub::BlockScan<Slot, one_block_threads>;
  __shared__ typename Scan::TempStorage scan_temp;
  const Slot entries = cells + 1;
  for (Slot c = threadIdx.x; c < entries; c += one_block_threads) start[c] = 0;
  __syncthreads();
  for (Slot i = threadIdx.x; i < n; i += one_block_threads)
    count_one(xyz, i, view, watch, keys, provisional, start);
  __syncthreads();
  const Slot per_thread = (entries + one_block_threads - 1) / one_block_threads;
  const Slot first = threadIdx.x * per_thread, last = min(first + per_thread, entries);
  Slot sum = 0;
  for (Slot c = first; c < last; ++c) sum += start[c];
  Slot offset;
  Scan(scan_temp).ExclusiveSum(sum, offset);
  for (Slot c = first; c < last; ++c) {
    const Slot count = start[c];
    start[c] = offset;
    offset += count;
  }
  __syncthreads();
  for (Slot i = threadIdx.x; i < n; i += one_block_threads)
    members[start[keys[i]] + provisional[i]] = i;
  __syncthreads();  // provisional[] read for the last time: it becomes the order
  for (Slot i = threadIdx.x; i < n; i += one_block_threads)
    place_one(xyz, members, start[keys[i]], start[keys[i] + 1], i, pos, provisional);
}

// Pass 2 is an exclusive scan of start[] in place. Pass 3: the particles of each cell, in the
// provisional order.
__global__ void scatter_cells_kernel(const std::uint32_t* keys, const Slot* provisional,
                                     const Slot* start, Slot n, Slot* members) {
  const Slot i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) members[start[keys[i]] + provisional[i]] = i;
}

// Pass 4, by particle (place_one). The scan of the cell costs less than the compute's own scan of
// it (every target tests every particle of its own cell).
__global__ void place_kernel(const float* __restrict__ xyz, const std::uint32_t* keys,
                             const Slot* start, const Slot* members, Slot n, float4* pos,
                             Slot* order) {
  const Slot i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) place_one(xyz, members, start[keys[i]], start[keys[i] + 1], i, pos, order);
}

// Pass 4, by cell: a thread per cell lists its particles by index (a rank per particle among the
// cell's few) and writes them to the cell's consecutive slots: the writes are coalesced and each
// particle's position is read once, where place_kernel reads the table at random per particle
// and writes at random. Cells of more than `warp_cell_from` particles are ranked by the whole
// warp together, one cell after another (a cluster would leave one thread with m^2 steps).
constexpr Slot warp_cell_from = 32;
__global__ void place_by_cell_kernel(const float* __restrict__ xyz, const Slot* start,
                                     const Slot* members, std::uint32_t cells, float4* pos,
                                     Slot* order) {
  const std::uint32_t c = blockIdx.x * blockDim.x + threadIdx.x;
  const int lane = threadIdx.x % 32;
  Slot first = 0, last = 0;
  if (c < cells) {
    first = start[c];
    last = start[c + 1];
  }
  const bool large = last - first > warp_cell_from;
  if (!large)
    for (Slot s = first; s < last; ++s)
      place_one(xyz, members, first, last, members[s], pos, order);
  for (unsigned ballot = __ballot_sync(0xffffffffu, large); ballot != 0; ballot &= ballot - 1) {
    const int owner = __ffs(ballot) - 1;
    const Slot f = __shfl_sync(0xffffffffu, first, owner),
               l = __shfl_sync(0xffffffffu, last, owner);
    for (Slot s = f + lane; s < l; s += 32) place_one(xyz, members, f, l, members[s], pos, order);
  }
}

__global__ void gather_kernel(const float* __restrict__ xyz, const Slot* order, Slot n,
                              float4* pos) {
  const Slot s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s < n) gather_one(xyz, order, s, pos);
}

struct IsCellHead {
  const std::uint64_t* keys;
  __host__ __device__ bool operator()(Slot s) const { return s == 0 || keys[s] != keys[s - 1]; }
};

// Compact, pass 1: unique keys, the final start entry, and each row's first unique cell.
__global__ void insert_rows_kernel(const std::uint64_t* keys, const Slot* run_start,
                                   const std::uint32_t* runs_ptr, Slot n, std::uint32_t dims0,
                                   std::uint64_t* cell_keys, Slot* cell_start,
                                   std::uint64_t* row_keys, uint2* row_cells, std::uint64_t mask,
                                   int shift) {
  const std::uint32_t runs = *runs_ptr;
  const std::uint32_t u = blockIdx.x * blockDim.x + threadIdx.x;
  if (u >= runs) return;
  const std::uint64_t key = keys[run_start[u]];
  cell_keys[u] = key;
  cell_start[u] = run_start[u];
  if (u == runs - 1) cell_start[runs] = n;
  const std::uint64_t row = key / dims0;
  if (u > 0 && keys[run_start[u - 1]] / dims0 == row) return;
  std::uint64_t h = row_hash(row, shift);
  for (;;) {
    const unsigned long long old =
        atomicCAS(reinterpret_cast<unsigned long long*>(&row_keys[h]),
                  static_cast<unsigned long long>(empty_row), static_cast<unsigned long long>(row));
    if (old == empty_row) {
      row_cells[h].x = u;
      return;
    }
    h = (h + 1) & mask;
  }
}

// Compact, pass 2: each row's end, written by the row's last unique cell.
__global__ void close_rows_kernel(const std::uint64_t* cell_keys, const std::uint32_t* runs_ptr,
                                  std::uint32_t dims0, const std::uint64_t* row_keys,
                                  uint2* row_cells, std::uint64_t mask, int shift) {
  const std::uint32_t runs = *runs_ptr;
  const std::uint32_t u = blockIdx.x * blockDim.x + threadIdx.x;
  if (u >= runs) return;
  const std::uint64_t row = cell_keys[u] / dims0;
  if (u + 1 < runs && cell_keys[u + 1] / dims0 == row) return;
  std::uint64_t h = row_hash(row, shift);
  while (row_keys[h] != row) h = (h + 1) & mask;
  row_cells[h].y = u + 1;
}

// Bits needed to hold every value below `count` (at least 1), and powers of two (no C++20 <bit>
// in CUDA translation units, which compile as C++17).
int key_bits(std::uint64_t count) {
  int bits = 1;
  while (bits < 64 && (count - 1) >> bits) ++bits;
  return bits;
}
std::uint64_t power_of_two_at_least(std::uint64_t v) {
  std::uint64_t p = 1;
  while (p < v) p <<= 1;
  return p;
}
int log2_of_power_of_two(std::uint64_t p) {
  int l = 0;
  while ((std::uint64_t{1} << l) < p) ++l;
  return l;
}

}  // namespace

void GridTables::build(const float* xyz, std::uint32_t n, const GridPlan& plan,
                       const PlannedBox& watch, cudaStream_t stream) {
  n_ = n;
  if (plan.dense)
    build_dense(xyz, plan, watch, stream);
  else
    build_compact(xyz, plan, watch, stream);
}

namespace {
// Reads the 4-byte order, not the slot's 16-byte float4 (the selection ran 39 us at 2^22
// points with it; ncu on the H200, 2026-12-02).
struct IsTarget {
  const Slot* order;
  std::uint32_t targets;
  __device__ bool operator()(Slot s) const { return order[s] < targets; }
};
}  // namespace

void GridTables::select_targets(std::uint32_t targets, cudaStream_t stream) {
  targets_.resize(std::max<std::uint32_t>(targets, 1));
  selected_.resize(1);
  const thrust::counting_iterator<std::uint32_t> slots(0);
  const IsTarget is_target{order_, targets};
  std::size_t temp_bytes = 0;
  RAYCUT_CUDA_CHECK(cub::DeviceSelect::If(nullptr, temp_bytes, slots, targets_.data(),
                                          selected_.data(), n_, is_target, stream));
  temp_.resize(std::max<std::size_t>(temp_bytes, 1));
  RAYCUT_CUDA_CHECK(cub::DeviceSelect::If(temp_.data(), temp_bytes, slots, targets_.data(),
                                          selected_.data(), n_, is_target, stream));
}

__global__ void gather_images_kernel(const Slot* order, const PointImage* image, Slot n,
                                     PointImage* slot_images) {
  const Slot s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s < n) slot_images[s] = image[order[s]];
}

SlotImages::~SlotImages() {
  if (done_) cudaEventDestroy(done_);
}

void SlotImages::reset(const Slot* order, std::uint32_t n, const PointImage* by_point) {
  const std::lock_guard<std::mutex> lock(mutex_);
  order_ = order;
  n_ = n;
  by_point_ = by_point;
  gathered_ = false;
}

const PointImage* SlotImages::on(void* stream_ptr) const {
  const auto stream = static_cast<cudaStream_t>(stream_ptr);
  const std::lock_guard<std::mutex> lock(mutex_);
  if (!gathered_) {
    table_.resize(std::max<std::uint32_t>(n_, 1));
    if (n_ > 0) {
      gather_images_kernel<<<blocks_for(n_, 256), 256, 0, stream>>>(order_, by_point_, n_,
                                                                    table_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
    }
    if (!done_) RAYCUT_CUDA_CHECK(cudaEventCreateWithFlags(&done_, cudaEventDisableTiming));
    RAYCUT_CUDA_CHECK(cudaEventRecord(done_, stream));
    gathered_ = true;
    gathered_on_ = stream;
  } else if (stream != gathered_on_) {
    RAYCUT_CUDA_CHECK(cudaStreamWaitEvent(stream, done_, 0));
  }
  return table_.data();
}

const DeferredImages* GridTables::slot_images(const PointImage* by_point) {
  slot_images_.reset(order_, n_, by_point);
  band_targets_.resize(std::size_t{n_} + 1);
  return &slot_images_;
}

GridPass GridTables::pass(const GridPlan& plan) const {
  GridPass p;
  p.particles = pos_.data();
  p.targets = targets_.data();
  p.geometry = plan.geometry;
  p.dense = plan.dense;
  p.dense_table.start = start_.data();
  p.compact_table = {cell_keys_.data(), start_.data(),
                     row_keys_.data(),  reinterpret_cast<const std::uint32_t*>(row_cells_.data()),
                     row_mask_,         row_shift_};
  p.kernel = plan.kernel;
  p.band_targets = band_targets_.size() > n_ ? band_targets_.data() : nullptr;
  return p;
}

// Radix sort of (key, index) on the bits the keys use; returns the sorted buffers.
template <class Key>
void GridTables::sort(DeviceBuffer<Key>& keys, DeviceBuffer<Key>& keys_alt, int bits,
                      Key*& sorted_keys, cudaStream_t stream) {
  cub::DoubleBuffer<Key> k(keys.data(), keys_alt.data());
  cub::DoubleBuffer<std::uint32_t> v(index_.data(), index_alt_.data());
  // The temporary size depends on (n, bits, key size) only: ask cub again only when they change.
  const std::uint64_t shape = (std::uint64_t{n_} << 16) | (bits << 4) | sizeof(Key);
  if (shape != sort_shape_) {
    RAYCUT_CUDA_CHECK(
        cub::DeviceRadixSort::SortPairs(nullptr, sort_temp_bytes_, k, v, n_, 0, bits, stream));
    sort_shape_ = shape;
  }
  std::size_t temp_bytes = sort_temp_bytes_;
  temp_.resize(std::max<std::size_t>(temp_bytes, 1));
  RAYCUT_CUDA_CHECK(
      cub::DeviceRadixSort::SortPairs(temp_.data(), temp_bytes, k, v, n_, 0, bits, stream));
  sorted_keys = k.Current();
  order_ = v.Current();
}

// start_[0, count) replaced in place by its prefix maximum.
void GridTables::prefix_maximum(std::uint64_t count, cudaStream_t stream) {
  const auto run = [&](void* temp, std::size_t& bytes) {
    return cub::DeviceScan::InclusiveScan(temp, bytes, start_.data(), start_.data(),
                                          ::cuda::maximum<std::uint32_t>{}, count, stream);
  };
  // The temporary size depends on the length only: ask cub again only when it changes.
  if (count != scan_shape_) {
    RAYCUT_CUDA_CHECK(run(nullptr, scan_temp_bytes_));
    scan_shape_ = count;
  }
  std::size_t temp_bytes = scan_temp_bytes_;
  temp_.resize(std::max<std::size_t>(temp_bytes, 1));
  RAYCUT_CUDA_CHECK(run(temp_.data(), temp_bytes));
}

void GridTables::build_dense(const float* xyz, const GridPlan& plan, const PlannedBox& watch,
                             cudaStream_t stream) {
  const std::uint64_t cells = plan.cells;
  const GridGeometry& view = plan.geometry;
  keys32_.resize(n_);
  index_.resize(n_);
  index_alt_.resize(n_);
  pos_.resize(n_);
  start_.resize(cells + 1);
  const auto blocks = [](std::uint64_t count) { return blocks_for(count, 256); };
  switch (plan.dense_build) {
    case DenseBuild::one_block:
      small_dense_build_kernel<<<1, one_block_threads, 0, stream>>>(
          xyz, n_, view, watch, static_cast<std::uint32_t>(cells), keys32_.data(), index_.data(),
          index_alt_.data(), start_.data(), pos_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
      order_ = index_.data();
      return;
    case DenseBuild::radix: {
      RAYCUT_CUDA_CHECK(
          cudaMemsetAsync(start_.data(), 0, (cells + 1) * sizeof(std::uint32_t), stream));
      keys32_alt_.resize(n_);
      keys_kernel<<<blocks(n_), 256, 0, stream>>>(xyz, n_, view, watch, keys32_.data(),
                                                  index_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
      std::uint32_t* sorted = nullptr;
      sort(keys32_, keys32_alt_, key_bits(cells), sorted, stream);
      run_ends_kernel<<<blocks(n_), 256, 0, stream>>>(xyz, sorted, order_, n_, start_.data(),
                                                      pos_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
      prefix_maximum(cells + 1, stream);
      return;
    }
    default:
      break;
  }
  // Counting sort: no radix passes, no table search; its atomics lose to the sort's streaming
  // at large N.
  RAYCUT_CUDA_CHECK(cudaMemsetAsync(start_.data(), 0, (cells + 1) * sizeof(std::uint32_t), stream));
  count_cells_kernel<<<blocks(n_), 256, 0, stream>>>(xyz, n_, view, watch, keys32_.data(),
                                                     index_.data(), start_.data());
  RAYCUT_CUDA_CHECK_LAUNCH();
  exclusive_sum(start_.data(), cells, start_.data(), temp_, stream);
  scatter_cells_kernel<<<blocks(n_), 256, 0, stream>>>(keys32_.data(), index_.data(), start_.data(),
                                                       n_, index_alt_.data());
  RAYCUT_CUDA_CHECK_LAUNCH();
  // The provisional ranks (index_) are read for the last time by the scatter: they become the
  // order.
  if (plan.dense_build == DenseBuild::counting_by_cell)
    place_by_cell_kernel<<<blocks(cells), 256, 0, stream>>>(xyz, start_.data(), index_alt_.data(),
                                                            static_cast<std::uint32_t>(cells),
                                                            pos_.data(), index_.data());
  else
    place_kernel<<<blocks(n_), 256, 0, stream>>>(xyz, keys32_.data(), start_.data(),
                                                 index_alt_.data(), n_, pos_.data(), index_.data());
  RAYCUT_CUDA_CHECK_LAUNCH();
  order_ = index_.data();
}

void GridTables::build_compact(const float* xyz, const GridPlan& plan, const PlannedBox& watch,
                               cudaStream_t stream) {
  const GridGeometry& view = plan.geometry;
  keys64_.resize(n_);
  keys64_alt_.resize(n_);
  index_.resize(n_);
  index_alt_.resize(n_);
  pos_.resize(n_);
  run_start_.resize(n_);
  keys_kernel<<<blocks_for(n_, 256), 256, 0, stream>>>(xyz, n_, view, watch, keys64_.data(),
                                                       index_.data());
  RAYCUT_CUDA_CHECK_LAUNCH();
  std::uint64_t* sorted = nullptr;
  sort(keys64_, keys64_alt_, key_bits(plan.cells), sorted, stream);
  gather_kernel<<<blocks_for(n_, 256), 256, 0, stream>>>(xyz, order_, n_, pos_.data());
  RAYCUT_CUDA_CHECK_LAUNCH();

  // First slot of every non-empty cell. Their number stays on the device: the tables are sized
  // for n cells (a compact grid has far more cells than points, so nearly every point heads its
  // own), which reads nothing back and keeps the build stream-ordered.
  runs_.resize(1);
  std::uint32_t* runs_device = runs_.data();
  const thrust::counting_iterator<std::uint32_t> slots(0);
  std::size_t temp_bytes = 0;
  RAYCUT_CUDA_CHECK(cub::DeviceSelect::If(nullptr, temp_bytes, slots, run_start_.data(),
                                          runs_device, n_, IsCellHead{sorted}, stream));
  temp_.resize(std::max<std::size_t>(temp_bytes, 1));
  RAYCUT_CUDA_CHECK(cub::DeviceSelect::If(temp_.data(), temp_bytes, slots, run_start_.data(),
                                          runs_device, n_, IsCellHead{sorted}, stream));

  cell_keys_.resize(n_);
  start_.resize(n_ + 1);
  const std::uint64_t capacity = power_of_two_at_least(std::max<std::uint64_t>(2ull * n_, 1024));
  row_keys_.resize(capacity);
  row_cells_.resize(capacity);
  row_mask_ = capacity - 1;
  row_shift_ = 64 - log2_of_power_of_two(capacity);
  RAYCUT_CUDA_CHECK(
      cudaMemsetAsync(row_keys_.data(), 0xFF, capacity * sizeof(std::uint64_t), stream));
  insert_rows_kernel<<<blocks_for(n_, 256), 256, 0, stream>>>(
      sorted, run_start_.data(), runs_device, n_, view.xgrid.dims[0], cell_keys_.data(),
      start_.data(), row_keys_.data(), row_cells_.data(), row_mask_, row_shift_);
  RAYCUT_CUDA_CHECK_LAUNCH();
  close_rows_kernel<<<blocks_for(n_, 256), 256, 0, stream>>>(
      cell_keys_.data(), runs_device, view.xgrid.dims[0], row_keys_.data(), row_cells_.data(),
      row_mask_, row_shift_);
  RAYCUT_CUDA_CHECK_LAUNCH();
}

}  // namespace raycut::detail::cuda
