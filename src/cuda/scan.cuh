// The exclusive prefix sum that the builds and lists share: counts (per particle, per cell, per
// target) into offsets, with the total after the last one. nvcc only.
#pragma once

#include <cuda_runtime.h>

#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/transform_iterator.h>

#include <cub/block/block_scan.cuh>
#include <cub/device/device_scan.cuh>

#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "raycut/detail/cuda/check.cuh"

namespace raycut::detail::cuda {

constexpr int one_block_scan_threads = 1024;
constexpr int one_block_scan_items = 16;  // per thread and tile
constexpr std::uint64_t one_block_scan_tile =
    std::uint64_t{one_block_scan_threads} * one_block_scan_items;
// Up to this many counts, one block walks them tile by tile.
constexpr std::uint64_t one_block_scan_limit = 4 * one_block_scan_tile;

// offsets[i] = counts[0] + ... + counts[i - 1] for i in [0, n]; counts and offsets may be the
// same array (each thread reads its items before the block's scan, and writes them after).
template <class Count, class Offset>
__global__ void __launch_bounds__(one_block_scan_threads)
    one_block_exclusive_sum(const Count* counts, std::uint64_t n, Offset* offsets) {
  using Scan = cub::BlockScan<Offset, one_block_scan_threads>;
  __shared__ typename Scan::TempStorage temp;
  Offset carry = 0;
  for (std::uint64_t tile = 0; tile < n; tile += one_block_scan_tile) {
    const std::uint64_t first = tile + std::uint64_t{threadIdx.x} * one_block_scan_items;
    Offset v[one_block_scan_items];
#pragma unroll
    for (int k = 0; k < one_block_scan_items; ++k)
      v[k] = first + k < n ? static_cast<Offset>(counts[first + k]) : Offset{0};
    Offset tile_total;
    Scan(temp).ExclusiveSum(v, v, tile_total);
#pragma unroll
    for (int k = 0; k < one_block_scan_items; ++k)
      if (first + k < n) offsets[first + k] = carry + v[k];
    carry += tile_total;
    __syncthreads();  // temp is used again
  }
  if (threadIdx.x == 0) offsets[n] = carry;
}

// counts[i] for i < n, then a zero: scanned as n + 1 inputs, the total lands in offsets[n].
template <class Count, class Offset>
struct CountOrZero {
  const Count* counts;
  std::uint64_t n;
  __host__ __device__ Offset operator()(std::uint64_t i) const {
    return i < n ? static_cast<Offset>(counts[i]) : Offset{0};
  }
};

// offsets[0, n] from counts[0, n) on `stream` (offsets[n]: the total; counts and offsets may be
// the same array); `temp` (resize(bytes), data()) holds CUB's storage. Small inputs take one
// block and one launch: CUB's scan is two (its tile states' initialisation, then the scan), about
// 4 us on an H100 at 10^4 counts, and a periodic build and list at that size run three.
template <class Count, class Offset, class Temp>
void exclusive_sum(const Count* counts, std::uint64_t n, Offset* offsets, Temp& temp,
                   cudaStream_t stream) {
  if (n <= one_block_scan_limit) {
    one_block_exclusive_sum<<<1, one_block_scan_threads, 0, stream>>>(counts, n, offsets);
    RAYCUT_CUDA_CHECK_LAUNCH();
    return;
  }
  const auto input = thrust::make_transform_iterator(thrust::counting_iterator<std::uint64_t>(0),
                                                     CountOrZero<Count, Offset>{counts, n});
  std::size_t temp_bytes = 0;
  RAYCUT_CUDA_CHECK(
      cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, input, offsets, n + 1, stream));
  temp.resize(std::max<std::size_t>(temp_bytes, 1));
  RAYCUT_CUDA_CHECK(
      cub::DeviceScan::ExclusiveSum(temp.data(), temp_bytes, input, offsets, n + 1, stream));
}

}  // namespace raycut::detail::cuda
