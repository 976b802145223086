// RAII device memory. Methods own DeviceBuffers; kernels get raw pointers.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <utility>

#include "core/validation.hpp"
#include "raycut/detail/cuda/check.cuh"

namespace raycut::detail::cuda {

// Throws Error(out_of_memory) saying what needed how much, when `bytes` exceeds free memory.
void require_device_memory(std::size_t bytes, const char* what);

template <class T>
class DeviceBuffer {
 public:
  DeviceBuffer() = default;
  explicit DeviceBuffer(std::size_t count) { resize(count); }
  ~DeviceBuffer() { release(); }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  DeviceBuffer(DeviceBuffer&& o) noexcept
      : data_(std::exchange(o.data_, nullptr)),
        size_(std::exchange(o.size_, 0)),
        capacity_(std::exchange(o.capacity_, 0)) {}
  DeviceBuffer& operator=(DeviceBuffer&& o) noexcept {
    if (this != &o) {
      release();
      data_ = std::exchange(o.data_, nullptr);
      size_ = std::exchange(o.size_, 0);
      capacity_ = std::exchange(o.capacity_, 0);
    }
    return *this;
  }

  // Reallocates only when growing; contents are not kept.
  void resize(std::size_t count) {
    if (count <= capacity_) {
      size_ = count;
      return;
    }
    release();
    if (cudaMalloc(&data_, count * sizeof(T)) != cudaSuccess) {
      (void)cudaGetLastError();  // clear the sticky allocation error
      data_ = nullptr;
      require_device_memory(count * sizeof(T), "a device buffer");
      throw_cuda(cudaErrorMemoryAllocation, "cudaMalloc", __FILE__, __LINE__);
    }
    size_ = capacity_ = count;
  }

  T* data() { return data_; }
  const T* data() const { return data_; }
  std::size_t size() const { return size_; }
  std::size_t bytes() const { return size_ * sizeof(T); }

 private:
  void release() noexcept {
    if (data_) cudaFree(data_);
    data_ = nullptr;
    size_ = capacity_ = 0;
  }
  T* data_ = nullptr;
  std::size_t size_ = 0, capacity_ = 0;
};

}  // namespace raycut::detail::cuda
