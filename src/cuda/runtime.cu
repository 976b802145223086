#include "cuda/runtime.hpp"

#include <cuda_runtime.h>

#include <cmath>
#include <string>

#include "core/validation.hpp"
#include "cuda/check.cuh"
#include "cuda/device_buffer.cuh"

namespace raycut::detail::cuda {

bool device_available() {
  int count = 0;
  if (cudaGetDeviceCount(&count) != cudaSuccess) {
    (void)cudaGetLastError();
    return false;
  }
  return count > 0;
}

void require_device_memory(std::size_t bytes, const char* what) {
  std::size_t free_bytes = 0, total_bytes = 0;
  RAYCUT_CUDA_CHECK(cudaMemGetInfo(&free_bytes, &total_bytes));
  if (bytes > free_bytes)
    throw Error(ErrorCode::out_of_memory,
                std::string("not enough device memory for ") + what + ": needs " +
                    format_bytes(static_cast<double>(bytes)) + ", the device has " +
                    format_bytes(static_cast<double>(free_bytes)) + " free of " +
                    format_bytes(static_cast<double>(total_bytes)));
}

namespace {

__global__ void first_non_finite_kernel(const float* xyz, std::size_t n,
                                        unsigned long long* first) {
  for (std::size_t i = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x; i < n;
       i += std::size_t{gridDim.x} * blockDim.x) {
    if (!isfinite(xyz[3 * i]) || !isfinite(xyz[3 * i + 1]) || !isfinite(xyz[3 * i + 2]))
      atomicMin(first, static_cast<unsigned long long>(i));
  }
}

}  // namespace

std::size_t first_non_finite(const float* device_xyz, std::size_t n) {
  if (n == 0) return 0;
  DeviceBuffer<unsigned long long> first(1);
  const unsigned long long none = n;
  RAYCUT_CUDA_CHECK(cudaMemcpy(first.data(), &none, sizeof none, cudaMemcpyHostToDevice));
  const unsigned blocks = static_cast<unsigned>(std::min<std::size_t>((n + 255) / 256, 65536));
  first_non_finite_kernel<<<blocks, 256>>>(device_xyz, n, first.data());
  RAYCUT_CUDA_CHECK_LAUNCH();
  unsigned long long result = 0;
  RAYCUT_CUDA_CHECK(cudaMemcpy(&result, first.data(), sizeof result, cudaMemcpyDeviceToHost));
  return static_cast<std::size_t>(result);
}

void DeviceFree::operator()(void* p) const noexcept {
  cudaFree(p);
}

DeviceMemory upload(const void* host, std::size_t bytes) {
  require_device_memory(bytes, "the positions");
  void* p = nullptr;
  RAYCUT_CUDA_CHECK(cudaMalloc(&p, bytes));
  DeviceMemory owned(p);
  RAYCUT_CUDA_CHECK(cudaMemcpy(p, host, bytes, cudaMemcpyHostToDevice));
  return owned;
}

void download(void* host, const void* device, std::size_t bytes) {
  RAYCUT_CUDA_CHECK(cudaMemcpy(host, device, bytes, cudaMemcpyDeviceToHost));
}

std::string device_name() {
  int device = 0;
  RAYCUT_CUDA_CHECK(cudaGetDevice(&device));
  cudaDeviceProp props{};
  RAYCUT_CUDA_CHECK(cudaGetDeviceProperties(&props, device));
  return props.name;
}

std::string runtime_version() {
  int v = 0;
  RAYCUT_CUDA_CHECK(cudaRuntimeGetVersion(&v));
  return std::to_string(v / 1000) + "." + std::to_string(v % 1000 / 10);
}

}  // namespace raycut::detail::cuda
