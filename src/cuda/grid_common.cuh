// Pieces shared by the CUDA grid methods (grid-paper, grid): the bounding box of device
// positions, reduced in one kernel and read back through mapped pinned memory.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>

#include "cuda/device_buffer.cuh"

namespace raycut::detail::cuda {

// The axis-aligned bounding box of n >= 1 device positions, on the host. One kernel (the last
// block finishes the reduction) and one stream synchronisation; buffers are kept between calls.
class BoundingBox {
 public:
  BoundingBox() = default;
  ~BoundingBox();
  BoundingBox(const BoundingBox&) = delete;
  BoundingBox& operator=(const BoundingBox&) = delete;

  void compute(const float* xyz, std::size_t n, float lo[3], float hi[3],
               cudaStream_t stream = nullptr);

 private:
  DeviceBuffer<float> partials_;    // 6 per block
  DeviceBuffer<unsigned> counter_;  // blocks done; the last one resets it to 0
  float* result_ = nullptr;         // mapped pinned host memory: lo[3], hi[3]
  float* device_result_ = nullptr;  // the same memory, as the device sees it
};

}  // namespace raycut::detail::cuda
