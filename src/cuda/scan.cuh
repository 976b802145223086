// The exclusive prefix sum that the builds and lists share: counts (per particle, per cell, per
// target) into offsets, with the total after the last one. nvcc only.
#pragma once

#include <cuda_runtime.h>

#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/transform_iterator.h>

#include <cub/device/device_scan.cuh>

#include <algorithm>
#include <cstddef>
#include <cstdint>

#include "raycut/detail/cuda/check.cuh"

namespace raycut::detail::cuda {

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
// the same array); `temp` (resize(bytes), data()) holds CUB's storage.
//
// One block instead of CUB's two launches (its tile states' initialisation, then the scan) was
// measured and dropped: one multiprocessor reading and writing 16 consecutive counts a thread
// took several microseconds per 16,384 counts (H100: docs/benchmarks.md, "Fewer kernels in a
// reused build"), more than the launch saved.
template <class Count, class Offset, class Temp>
void exclusive_sum(const Count* counts, std::uint64_t n, Offset* offsets, Temp& temp,
                   cudaStream_t stream) {
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
