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

// Where a DeviceBuffer's memory comes from.
enum class Allocation {
  // cudaMalloc / cudaFree: structures that live as long as their method and only grow.
  dedicated,
  // raycut's stream-ordered pool of the current device, whose freed blocks stay mapped for the
  // next allocation: outputs made afresh per call (a list per Python call). cudaMalloc and
  // cudaFree of the ~1 GB list of 2^20 particles with shifts cost ~0.5 ms per call, a quarter of
  // the list itself (docs/python.md, "Where the time goes").
  pooled,
};
// nullptr when the device cannot hold `bytes` even after the pool gave its cached blocks back.
void* pooled_allocate(std::size_t bytes);
// After every stream's work (the block may still be read, as cudaFree waits too).
void pooled_free(void* p) noexcept;
// Stream-ordered on `stream` from the same pool, waiting for nothing (a CUDA graph captures it
// as an allocation node); free with cudaFreeAsync. Not the device's default pool: that one gives
// its freed blocks back to the driver at every synchronisation (release threshold 0), so each
// call would map its memory afresh. Throws out_of_memory when the pool cannot grow.
void* pooled_allocate_async(std::size_t bytes, cudaStream_t stream);

template <class T, Allocation A = Allocation::dedicated>
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
    if (!allocate(count * sizeof(T))) {
      data_ = nullptr;
      require_device_memory(count * sizeof(T), "a device buffer");
      throw_cuda(cudaErrorMemoryAllocation, "cudaMalloc", __FILE__, __LINE__);
    }
    size_ = capacity_ = count;
  }

  // As resize(), the first `keep` entries kept: copied on `stream` when it reallocates (the old
  // block is freed after the copy, as cudaFree waits for the device).
  void resize_keeping(std::size_t count, std::size_t keep, cudaStream_t stream) {
    if (count <= capacity_) {
      size_ = count;
      return;
    }
    DeviceBuffer bigger(count);
    if (keep > 0)
      RAYCUT_CUDA_CHECK(
          cudaMemcpyAsync(bigger.data_, data_, keep * sizeof(T), cudaMemcpyDeviceToDevice, stream));
    *this = std::move(bigger);
  }

  T* data() { return data_; }
  const T* data() const { return data_; }
  std::size_t size() const { return size_; }
  std::size_t bytes() const { return size_ * sizeof(T); }
  std::size_t capacity_bytes() const { return capacity_ * sizeof(T); }

 private:
  bool allocate(std::size_t bytes) {
    if constexpr (A == Allocation::pooled) {
      data_ = static_cast<T*>(pooled_allocate(bytes));
      return data_ != nullptr;
    } else {
      if (cudaMalloc(&data_, bytes) == cudaSuccess) return true;
      (void)cudaGetLastError();  // clear the sticky allocation error
      return false;
    }
  }
  void release() noexcept {
    if (data_) {
      if constexpr (A == Allocation::pooled)
        pooled_free(data_);
      else
        cudaFree(data_);
    }
    data_ = nullptr;
    size_ = capacity_ = 0;
  }
  T* data_ = nullptr;
  std::size_t size_ = 0, capacity_ = 0;
};

template <class T>
using PooledBuffer = DeviceBuffer<T, Allocation::pooled>;

}  // namespace raycut::detail::cuda
