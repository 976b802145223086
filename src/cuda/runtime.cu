#include "cuda/runtime.hpp"

#include <cuda_runtime.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <mutex>
#include <string>
#include <vector>

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

// One device word per host thread and device, made once: the check runs at every build, and a
// cudaMalloc, a cudaFree and two pageable copies per call cost ~30 us, more than a whole build at
// 1,000 particles.
class DeviceWords {
 public:
  ~DeviceWords() {
    for (void* w : words_)  // at exit the runtime may be gone already: errors are ignored
      if (w) cudaFree(w);
  }
  unsigned long long* current() {
    int device = 0;
    RAYCUT_CUDA_CHECK(cudaGetDevice(&device));
    if (words_.size() <= static_cast<std::size_t>(device)) words_.resize(device + 1, nullptr);
    if (!words_[device]) RAYCUT_CUDA_CHECK(cudaMalloc(&words_[device], sizeof(unsigned long long)));
    return static_cast<unsigned long long*>(words_[device]);
  }

 private:
  std::vector<void*> words_;
};

std::size_t first_non_finite(const float* device_xyz, std::size_t n, void* stream) {
  if (n == 0) return 0;
  thread_local DeviceWords words;
  unsigned long long* first = words.current();
  const auto s = static_cast<cudaStream_t>(stream);
  RAYCUT_CUDA_CHECK(cudaMemsetAsync(first, 0xFF, sizeof *first, s));  // none found yet
  const unsigned blocks = static_cast<unsigned>(std::min<std::size_t>((n + 255) / 256, 65536));
  first_non_finite_kernel<<<blocks, 256, 0, s>>>(device_xyz, n, first);
  RAYCUT_CUDA_CHECK_LAUNCH();
  unsigned long long found = 0;
  read_back(&found, first, sizeof found, stream);
  return static_cast<std::size_t>(std::min<unsigned long long>(found, n));
}

namespace {
struct PinnedBlock {
  static constexpr std::size_t bytes = 64;
  void* host = nullptr;
  PinnedBlock() {
    RAYCUT_CUDA_CHECK(cudaHostAlloc(&host, bytes, cudaHostAllocPortable));  // any device
  }
  ~PinnedBlock() { cudaFreeHost(host); }
};
}  // namespace

void read_back(void* host, const void* device, std::size_t bytes, void* stream) {
  thread_local PinnedBlock block;
  if (bytes > PinnedBlock::bytes)
    throw Error(ErrorCode::internal, "read_back of more than 64 bytes");
  const auto s = static_cast<cudaStream_t>(stream);
  RAYCUT_CUDA_CHECK(cudaMemcpyAsync(block.host, device, bytes, cudaMemcpyDeviceToHost, s));
  RAYCUT_CUDA_CHECK(cudaStreamSynchronize(s));
  std::memcpy(host, block.host, bytes);
}

namespace {
// raycut's pool of each device, made on first use and kept for the process (the driver frees it
// with the context). Freed blocks stay with the pool (no release threshold) until an allocation
// does not fit.
cudaMemPool_t device_pool() {
  static std::mutex mutex;
  static std::vector<cudaMemPool_t> pools;
  int device = 0;
  RAYCUT_CUDA_CHECK(cudaGetDevice(&device));
  std::lock_guard<std::mutex> lock(mutex);
  if (pools.size() <= static_cast<std::size_t>(device)) pools.resize(device + 1, nullptr);
  if (!pools[device]) {
    cudaMemPoolProps props{};
    props.allocType = cudaMemAllocationTypePinned;
    props.location.type = cudaMemLocationTypeDevice;
    props.location.id = device;
    RAYCUT_CUDA_CHECK(cudaMemPoolCreate(&pools[device], &props));
    std::uint64_t keep = ~std::uint64_t{0};
    RAYCUT_CUDA_CHECK(
        cudaMemPoolSetAttribute(pools[device], cudaMemPoolAttrReleaseThreshold, &keep));
  }
  return pools[device];
}
}  // namespace

// On the legacy default stream, which orders with the library's and the caller's blocking
// streams; a block comes back to the pool only after a device-wide synchronisation
// (pooled_free), so whatever stream uses it next finds it idle.
void* pooled_allocate(std::size_t bytes) {
  cudaMemPool_t pool = device_pool();
  void* p = nullptr;
  if (cudaMallocFromPoolAsync(&p, bytes, pool, cudaStreamLegacy) == cudaSuccess) return p;
  (void)cudaGetLastError();
  // The cached blocks back to the device, then once more.
  if (cudaDeviceSynchronize() == cudaSuccess && cudaMemPoolTrimTo(pool, 0) == cudaSuccess &&
      cudaMallocFromPoolAsync(&p, bytes, pool, cudaStreamLegacy) == cudaSuccess)
    return p;
  (void)cudaGetLastError();
  return nullptr;
}

void* pooled_allocate_async(std::size_t bytes, cudaStream_t stream) {
  cudaMemPool_t pool = device_pool();
  void* p = nullptr;
  if (cudaMallocFromPoolAsync(&p, bytes, pool, stream) == cudaSuccess) return p;
  (void)cudaGetLastError();
  // The blocks already idle back to the device (no wait), then once more.
  if (cudaMemPoolTrimTo(pool, 0) == cudaSuccess &&
      cudaMallocFromPoolAsync(&p, bytes, pool, stream) == cudaSuccess)
    return p;
  (void)cudaGetLastError();
  throw Error(ErrorCode::out_of_memory,
              "device memory: " + std::to_string(bytes) + " bytes do not fit on the device");
}

// On the block's own device, which need not be the current one when the buffer dies.
void pooled_free(void* p) noexcept {
  int current = -1;
  cudaPointerAttributes where{};
  const bool elsewhere = cudaGetDevice(&current) == cudaSuccess &&
                         cudaPointerGetAttributes(&where, p) == cudaSuccess && where.device >= 0 &&
                         where.device != current;
  (void)cudaGetLastError();  // a failed query is not the caller's error
  if (elsewhere) cudaSetDevice(where.device);
  cudaDeviceSynchronize();
  cudaFreeAsync(p, cudaStreamLegacy);
  if (elsewhere) cudaSetDevice(current);
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

void copy(void* to, const void* from, std::size_t bytes) {
  if (bytes > 0) RAYCUT_CUDA_CHECK(cudaMemcpy(to, from, bytes, cudaMemcpyDefault));
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
    if (!(d2 <= limit_squared)) *moved = 1u;  // NaN too; racing writes of the same value
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

bool capturing(void* stream) {
  cudaStreamCaptureStatus status = cudaStreamCaptureStatusNone;
  RAYCUT_CUDA_CHECK(cudaStreamIsCapturing(static_cast<cudaStream_t>(stream), &status));
  return status != cudaStreamCaptureStatusNone;
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
