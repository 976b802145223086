// Pieces shared by the CUDA grid methods (grid-paper, grid): the bounding box of device
// positions, reduced in one kernel and read back through mapped pinned memory.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>

#include "cuda/device_buffer.cuh"

namespace raycut::detail::cuda {

// What the bounding-box kernel leaves in mapped pinned memory; `sequence` is written last.
struct BoxResult {
  float lo[3], hi[3];
  unsigned sequence;
};

// The axis-aligned bounding box of n >= 1 device positions, on the host. One kernel (the last
// block finishes the reduction), awaited by polling its result in mapped memory (sooner than a
// stream synchronisation); buffers are kept between calls.
class BoundingBox {
 public:
  BoundingBox() = default;
  ~BoundingBox();
  BoundingBox(const BoundingBox&) = delete;
  BoundingBox& operator=(const BoundingBox&) = delete;

  void compute(const float* xyz, std::size_t n, float lo[3], float hi[3],
               cudaStream_t stream = nullptr);

 private:
  DeviceBuffer<float> partials_;        // 6 per block
  DeviceBuffer<unsigned> counter_;      // blocks done; the last one resets it to 0
  BoxResult* result_ = nullptr;         // mapped pinned host memory
  BoxResult* device_result_ = nullptr;  // the same memory, as the device sees it
  unsigned sequence_ = 0;               // of the last call
};

}  // namespace raycut::detail::cuda
