#include <cuda_runtime.h>

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

// One thread per row: the row's entries get its index (rows are short: tens of entries).
__global__ void expand_rows(const std::uint64_t* offsets, std::size_t n, std::int64_t* i) {
  const std::size_t row = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
  if (row >= n) return;
  const std::uint64_t end = offsets[row + 1];
  for (std::uint64_t e = offsets[row]; e < end; ++e) i[e] = static_cast<std::int64_t>(row);
}

__global__ void widen(const std::uint32_t* indices, std::uint64_t pairs, std::int64_t* j) {
  const std::uint64_t e = blockIdx.x * std::uint64_t{blockDim.x} + threadIdx.x;
  if (e < pairs) j[e] = indices[e];
}

unsigned blocks(std::uint64_t work, unsigned threads) {
  return static_cast<unsigned>((work + threads - 1) / threads);
}

}  // namespace

void* device_alloc(std::size_t bytes) {
  void* p = nullptr;
  check(cudaMalloc(&p, bytes == 0 ? 1 : bytes), "cudaMalloc");
  return p;
}

void device_free(void* p) noexcept {
  cudaFree(p);
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
  expand_rows<<<blocks(n, threads), threads, 0, s>>>(offsets, n, i);
  check(cudaGetLastError(), "expand_rows launch");
  widen<<<blocks(pairs, threads), threads, 0, s>>>(indices, pairs, j);
  check(cudaGetLastError(), "widen launch");
  check(cudaStreamSynchronize(s), "csr_to_coo");
}

}  // namespace raycut_py
