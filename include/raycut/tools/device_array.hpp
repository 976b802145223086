// A copy of a host float array in CUDA device memory, for programs without CUDA code of their own:
// benchmarks whose positions start on the device, tests and device-side kernel inputs.
#pragma once

#include <cstddef>
#include <vector>

#include "raycut/engine.hpp"

namespace raycut {

// Throws Error(unsupported) when raycut was built without CUDA, and Error(out_of_memory) when
// the copy does not fit on the device.
class DeviceArray {
 public:
  explicit DeviceArray(const std::vector<float>& values);
  ~DeviceArray();
  DeviceArray(DeviceArray&&) noexcept;
  DeviceArray& operator=(DeviceArray&&) noexcept;
  const float* data() const { return data_; }
  float* data() { return data_; }
  std::size_t size() const { return size_; }
  // The array as (N,3) positions.
  PositionsView view() const { return {data_, size_ / 3, MemorySpace::device}; }

 private:
  float* data_ = nullptr;
  std::size_t size_ = 0;  // floats
};

}  // namespace raycut
