#include "cuda/runtime.hpp"

#include <cuda_runtime.h>

#include <cmath>
#include <string>

#include "core/validation.hpp"
#include "cuda/device_buffer.cuh"
#include "raycut/detail/cuda/check.cuh"

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
  if (!device_available())
    throw Error(ErrorCode::unsupported,
                "device memory asked for, but no CUDA device is usable in this process");
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

DeviceMemory copy_on_device(const void* device, std::size_t bytes, void* stream) {
  require_device_memory(bytes, "a copy of the positions");
  void* p = nullptr;
  RAYCUT_CUDA_CHECK(cudaMalloc(&p, bytes));
  DeviceMemory owned(p);
  RAYCUT_CUDA_CHECK(cudaMemcpyAsync(p, device, bytes, cudaMemcpyDeviceToDevice,
                                    static_cast<cudaStream_t>(stream)));
  return owned;
}

namespace {
__global__ void moved_beyond_kernel(const float* now, const float* then, std::size_t n,
                                    float limit_squared, unsigned* moved) {
  for (std::size_t i = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x; i < n;
       i += std::size_t{gridDim.x} * blockDim.x) {
    float d2 = 0;
    for (int a = 0; a < 3; ++a) {
      const float d = now[3 * i + a] - then[3 * i + a];
      d2 += d * d;
    }
    if (!(d2 <= limit_squared)) *moved = 1u;  // racing writes of the same value
  }
}
}  // namespace

bool moved_beyond(const float* now, const float* then, std::size_t n, float distance,
                  void* stream) {
  const auto s = static_cast<cudaStream_t>(stream);
  // A pinned, mapped flag: the kernel writes it, the host reads it after the stream gets there.
  static thread_local unsigned* flag = [] {
    unsigned* p = nullptr;
    RAYCUT_CUDA_CHECK(
        cudaHostAlloc(reinterpret_cast<void**>(&p), sizeof(unsigned), cudaHostAllocMapped));
    return p;
  }();
  *flag = 0;
  unsigned* device_flag = nullptr;
  RAYCUT_CUDA_CHECK(cudaHostGetDevicePointer(reinterpret_cast<void**>(&device_flag), flag, 0));
  const unsigned blocks = static_cast<unsigned>(std::min<std::size_t>((n + 255) / 256, 4096));
  if (n > 0)
    moved_beyond_kernel<<<blocks, 256, 0, s>>>(now, then, n, distance * distance, device_flag);
  RAYCUT_CUDA_CHECK_LAUNCH();
  RAYCUT_CUDA_CHECK(cudaStreamSynchronize(s));
  return *flag != 0;
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
