#include <cuda_runtime.h>

#include <cstdint>
#include <string>

#include "device.hpp"
#include "raycut/error.hpp"

namespace raycut_py {
namespace {

void check(cudaError_t status, const char* what) {
  if (status == cudaSuccess) return;
  const auto code = status == cudaErrorMemoryAllocation ? raycut::ErrorCode::out_of_memory
                                                        : raycut::ErrorCode::backend;
  cudaGetLastError();  // clear a non-sticky error
  throw raycut::Error(code,
                      std::string("raycut (python): ") + what + ": " + cudaGetErrorString(status));
}

// A warp per row: the lanes write the row's entries side by side (coalesced), where a thread
// per row wrote 32 scattered runs per store.
__global__ void expand_rows(const std::uint64_t* offsets, std::size_t n, std::int64_t* i) {
  const std::size_t row = (blockIdx.x * std::size_t{blockDim.x} + threadIdx.x) / 32;
  if (row >= n) return;
  const std::uint64_t end = offsets[row + 1];
  for (std::uint64_t e = offsets[row] + threadIdx.x % 32; e < end; e += 32)
    i[e] = static_cast<std::int64_t>(row);
}

__global__ void widen(const std::uint32_t* indices, std::uint64_t pairs, std::int64_t* j) {
  const std::uint64_t e = blockIdx.x * std::uint64_t{blockDim.x} + threadIdx.x;
  if (e < pairs) j[e] = indices[e];
}

unsigned blocks(std::uint64_t work, unsigned threads) {
  return static_cast<unsigned>((work + threads - 1) / threads);
}

}  // namespace

// Outputs come from the device's stream-ordered pool, kept between calls (release threshold at
// its maximum): a list of 58M pairs needs about 1 GB per call, and mapping and unmapping that
// much with cudaMalloc / cudaFree costs more than the list itself.
void* device_alloc(std::size_t bytes) {
  static const bool pooled = [] {
    int device = 0;
    cudaMemPool_t pool;
    if (cudaGetDevice(&device) != cudaSuccess ||
        cudaDeviceGetDefaultMemPool(&pool, device) != cudaSuccess) {
      (void)cudaGetLastError();
      return false;
    }
    std::uint64_t keep = ~std::uint64_t{0};
    return cudaMemPoolSetAttribute(pool, cudaMemPoolAttrReleaseThreshold, &keep) == cudaSuccess;
  }();
  (void)pooled;
  void* p = nullptr;
  check(cudaMallocAsync(&p, bytes == 0 ? 1 : bytes, nullptr), "cudaMallocAsync");
  return p;
}

// The caller's framework may still read the array on a stream of its own: wait for the whole
// device first, as cudaFree does, then return the block to the pool (no unmapping).
void device_free(void* p) noexcept {
  cudaDeviceSynchronize();
  cudaFreeAsync(p, nullptr);
}

int current_device() {
  int device = 0;
  check(cudaGetDevice(&device), "cudaGetDevice");
  return device;
}

int current_device_or_none() noexcept {
  int device = 0;
  if (cudaGetDevice(&device) != cudaSuccess) {
    (void)cudaGetLastError();
    return -1;
  }
  return device;
}

void device_copy(void* dst, const void* src, std::size_t bytes, void* stream) {
  if (bytes == 0) return;
  const auto s = static_cast<cudaStream_t>(stream);
  check(cudaMemcpyAsync(dst, src, bytes, cudaMemcpyDeviceToDevice, s), "cudaMemcpyAsync");
  check(cudaStreamSynchronize(s), "device_copy");
}

void csr_to_coo(const std::uint64_t* offsets, const std::uint32_t* indices, std::size_t n,
                std::uint64_t pairs, std::int64_t* i, std::int64_t* j, void* stream) {
  if (n == 0 || pairs == 0) return;
  const auto s = static_cast<cudaStream_t>(stream);
  constexpr unsigned threads = 256;
  expand_rows<<<blocks(std::uint64_t{n} * 32, threads), threads, 0, s>>>(offsets, n, i);
  check(cudaGetLastError(), "expand_rows launch");
  widen<<<blocks(pairs, threads), threads, 0, s>>>(indices, pairs, j);
  check(cudaGetLastError(), "widen launch");
  check(cudaStreamSynchronize(s), "csr_to_coo");
}

}  // namespace raycut_py
