#include <cuda_runtime.h>

#include <cstdint>
#include <string>

#include "cuda/device_buffer.cuh"  // raycut's pool
#include "cuda/runtime.hpp"        // capturing()
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

template <class Index>
__global__ void summarise(const Index* index, std::size_t n, unsigned long long* unsorted,
                          std::int64_t* ends) {
  const std::size_t k = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
  if (k == 0) {
    ends[0] = index[0];
    ends[1] = index[n - 1];
  }
  if (k + 1 < n && index[k] > index[k + 1]) atomicMin(unsorted, static_cast<unsigned long long>(k));
}

// Entry i (0 .. n) starts every system in (index[i - 1], index[i]] (index[-1] = -1, index[n] =
// systems): with a sorted index, each offset is written once.
template <class Index>
__global__ void boundaries(const Index* index, std::size_t n, std::size_t systems,
                           std::uint64_t* offsets) {
  const std::size_t i = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
  if (i > n) return;
  const std::int64_t lo = i == 0 ? -1 : static_cast<std::int64_t>(index[i - 1]);
  const std::int64_t hi =
      i == n ? static_cast<std::int64_t>(systems) : static_cast<std::int64_t>(index[i]);
  for (std::int64_t s = lo + 1; s <= hi; ++s) offsets[s] = i;
}

unsigned blocks(std::uint64_t work, unsigned threads) {
  return static_cast<unsigned>((work + threads - 1) / threads);
}

// A small device scratch from the pool, freed on scope exit (after the stream's work).
struct Scratch {
  void* p;
  explicit Scratch(std::size_t bytes) : p(device_alloc(bytes)) {}
  ~Scratch() { device_free(p); }
};

}  // namespace

// Outputs come from raycut's stream-ordered pool (src/cuda/device_buffer.cuh), kept between
// calls: a list of 58M pairs needs about 1 GB per call, and mapping and unmapping that much with
// cudaMalloc / cudaFree costs more than the list itself. Not the device's default pool: its
// release threshold is every other library's setting too (CuPy's async allocator uses it).
void* device_alloc(std::size_t bytes) {
  void* p = raycut::detail::cuda::pooled_allocate(bytes == 0 ? 1 : bytes);
  if (p == nullptr)
    throw raycut::Error(raycut::ErrorCode::out_of_memory,
                        "raycut (python): not enough device memory for an output of " +
                            std::to_string(bytes) + " bytes");
  return p;
}

// The caller's framework may still read the array on a stream of its own: the pool takes the
// block back after the whole device is idle, as cudaFree would wait.
void device_free(void* p) noexcept {
  raycut::detail::cuda::pooled_free(p);
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
}

void synchronize(void* stream) {
  check(cudaStreamSynchronize(static_cast<cudaStream_t>(stream)), "cudaStreamSynchronize");
}

IndexSummary summarise_index(const void* index, bool wide, std::size_t n, void* stream) {
  const auto s = static_cast<cudaStream_t>(stream);
  struct Words {
    unsigned long long unsorted;
    std::int64_t ends[2];
  };
  Scratch scratch(sizeof(Words));
  auto* words = static_cast<Words*>(scratch.p);
  const unsigned long long sorted = n - 1;
  check(cudaMemcpyAsync(&words->unsorted, &sorted, sizeof sorted, cudaMemcpyHostToDevice, s),
        "cudaMemcpyAsync");
  constexpr unsigned threads = 256;
  if (wide)
    summarise<<<blocks(n, threads), threads, 0, s>>>(static_cast<const std::int64_t*>(index), n,
                                                     &words->unsorted, words->ends);
  else
    summarise<<<blocks(n, threads), threads, 0, s>>>(static_cast<const std::int32_t*>(index), n,
                                                     &words->unsorted, words->ends);
  check(cudaGetLastError(), "summarise launch");
  Words host{};
  check(cudaMemcpyAsync(&host, words, sizeof host, cudaMemcpyDeviceToHost, s), "cudaMemcpyAsync");
  check(cudaStreamSynchronize(s), "summarise_index");
  IndexSummary out{host.ends[0], host.ends[1], host.unsorted, 0, 0};
  if (out.unsorted + 1 < n) {  // the two values the error message names
    const std::size_t size = wide ? 8 : 4;
    const auto* at = static_cast<const unsigned char*>(index) + out.unsorted * size;
    std::int64_t pair[2] = {0, 0};
    if (wide) {
      check(cudaMemcpy(pair, at, 2 * size, cudaMemcpyDeviceToHost), "cudaMemcpy");
    } else {
      std::int32_t narrow[2];
      check(cudaMemcpy(narrow, at, 2 * size, cudaMemcpyDeviceToHost), "cudaMemcpy");
      pair[0] = narrow[0];
      pair[1] = narrow[1];
    }
    out.here = pair[0];
    out.after = pair[1];
  }
  return out;
}

void index_offsets(const void* index, bool wide, std::size_t n, std::size_t systems,
                   std::uint64_t* host_offsets, void* stream) {
  const auto s = static_cast<cudaStream_t>(stream);
  const std::size_t bytes = (systems + 1) * sizeof(std::uint64_t);
  Scratch offsets(bytes);
  auto* out = static_cast<std::uint64_t*>(offsets.p);
  constexpr unsigned threads = 256;
  if (wide)
    boundaries<<<blocks(n + 1, threads), threads, 0, s>>>(static_cast<const std::int64_t*>(index),
                                                          n, systems, out);
  else
    boundaries<<<blocks(n + 1, threads), threads, 0, s>>>(static_cast<const std::int32_t*>(index),
                                                          n, systems, out);
  check(cudaGetLastError(), "boundaries launch");
  check(cudaMemcpyAsync(host_offsets, out, bytes, cudaMemcpyDeviceToHost, s), "cudaMemcpyAsync");
  check(cudaStreamSynchronize(s), "index_offsets");
}

namespace {
__global__ void compare_bytes(const unsigned char* a, const unsigned char* b, std::size_t bytes,
                              std::int64_t* count, std::int64_t code, int* raised) {
  bool differs = false;
  for (std::size_t k = threadIdx.x; k < bytes; k += blockDim.x) differs = differs || a[k] != b[k];
  if (__syncthreads_or(differs) && threadIdx.x == 0) {
    *count = code;
    *raised = 1;
  }
}
}  // namespace

// No CUDA call until the first compare(): a CPU caller never makes one.
ChangeFlag::ChangeFlag() = default;

ChangeFlag::~ChangeFlag() {
  if (done_) cudaEventDestroy(static_cast<cudaEvent_t>(done_));
  if (host_) cudaFreeHost(host_);
}

void ChangeFlag::compare(const void* a, const void* b, std::size_t bytes, std::int64_t* count,
                         std::int64_t code, void* stream) {
  const auto s = static_cast<cudaStream_t>(stream);
  if (!host_) {
    check(cudaHostAlloc(reinterpret_cast<void**>(&host_), sizeof(int), cudaHostAllocMapped),
          "cudaHostAlloc");
    *host_ = 0;
    check(cudaHostGetDevicePointer(reinterpret_cast<void**>(&device_), host_, 0),
          "cudaHostGetDevicePointer");
  }
  compare_bytes<<<1, 128, 0, s>>>(static_cast<const unsigned char*>(a),
                                  static_cast<const unsigned char*>(b), bytes, count, code,
                                  device_);
  check(cudaGetLastError(), "compare_bytes launch");
  if (raycut::detail::cuda::capturing(s)) return;
  if (!done_) {
    cudaEvent_t event = nullptr;
    check(cudaEventCreateWithFlags(&event, cudaEventDisableTiming), "cudaEventCreate");
    done_ = event;
  }
  check(cudaEventRecord(static_cast<cudaEvent_t>(done_), s), "cudaEventRecord");
  pending_ = true;
}

bool ChangeFlag::raised(void* stream) {
  if (!pending_ || raycut::detail::cuda::capturing(stream)) return false;
  const cudaError_t status = cudaEventQuery(static_cast<cudaEvent_t>(done_));
  if (status == cudaErrorNotReady) return false;
  check(status, "cudaEventQuery");
  pending_ = false;
  const bool was = *static_cast<volatile int*>(host_) != 0;
  *host_ = 0;
  return was;
}

}  // namespace raycut_py
