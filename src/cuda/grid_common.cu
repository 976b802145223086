#include <algorithm>
#include <atomic>
#include <cfloat>
#include <cstdint>

#include "cuda/grid_common.cuh"

namespace raycut::detail::cuda {
namespace {

constexpr int bbox_block = 256;
constexpr int bbox_max_blocks = 528;  // four per SM of an H100: enough to stream the positions

__device__ __forceinline__ void widen(float lo[3], float hi[3], float x, float y, float z) {
  lo[0] = fminf(lo[0], x), hi[0] = fmaxf(hi[0], x);
  lo[1] = fminf(lo[1], y), hi[1] = fmaxf(hi[1], y);
  lo[2] = fminf(lo[2], z), hi[2] = fmaxf(hi[2], z);
}

// Min and max of all threads' lo[3], hi[3] into v[6] of thread 0 (lo then hi).
__device__ __forceinline__ void block_reduce(const float lo[3], const float hi[3], float v[6]) {
  __shared__ float warp_values[bbox_block / 32][6];
  for (int a = 0; a < 3; ++a) v[a] = lo[a], v[3 + a] = hi[a];
#pragma unroll
  for (int offset = 16; offset > 0; offset /= 2)
    for (int k = 0; k < 6; ++k) {
      const float o = __shfl_xor_sync(0xffffffffu, v[k], offset);
      v[k] = k < 3 ? fminf(v[k], o) : fmaxf(v[k], o);
    }
  if (threadIdx.x % 32 == 0)
    for (int k = 0; k < 6; ++k) warp_values[threadIdx.x / 32][k] = v[k];
  __syncthreads();
  if (threadIdx.x == 0)
    for (int w = 1; w < bbox_block / 32; ++w)
      for (int k = 0; k < 6; ++k)
        v[k] = k < 3 ? fminf(v[k], warp_values[w][k]) : fmaxf(v[k], warp_values[w][k]);
  __syncthreads();
}

// Each block reduces its share to 6 partials; the last block to finish reduces the partials.
// Positions 16-byte aligned (cudaMalloc's) are read as float4, three per four particles (x y z x |
// y z x y | z x y z), 12 us at 2^20 particles (Nsight Compute) where one float per thread per
// load took 18; other pointers one float at a time.
__global__ void __launch_bounds__(bbox_block)
    bounding_box_kernel(const float* xyz, std::size_t n, float* partials, unsigned* counter,
                        BoxResult* result, unsigned sequence) {
  __shared__ bool last;
  float lo[3] = {FLT_MAX, FLT_MAX, FLT_MAX}, hi[3] = {-FLT_MAX, -FLT_MAX, -FLT_MAX};
  const std::size_t thread = blockIdx.x * std::size_t{bbox_block} + threadIdx.x;
  const std::size_t threads = std::size_t{gridDim.x} * bbox_block;
  std::size_t scalar_from = 0;
  if (reinterpret_cast<std::uintptr_t>(xyz) % 16 == 0) {
    const float4* quads = reinterpret_cast<const float4*>(xyz);
    const std::size_t groups = n / 4;
    constexpr int U = 2;  // groups in flight per thread: 6 loads
    for (std::size_t g = thread; g < groups; g += U * threads) {
      float4 q[U][3];
#pragma unroll
      for (int u = 0; u < U; ++u) {
        const std::size_t h = g + u * threads < groups ? g + u * threads : g;
#pragma unroll
        for (int k = 0; k < 3; ++k) q[u][k] = __ldg(quads + 3 * h + k);
      }
#pragma unroll
      for (int u = 0; u < U; ++u) {
        const float4 a = q[u][0], b = q[u][1], c = q[u][2];
        widen(lo, hi, a.x, a.y, a.z);
        widen(lo, hi, a.w, b.x, b.y);
        widen(lo, hi, b.z, b.w, c.x);
        widen(lo, hi, c.y, c.z, c.w);
      }
    }
    scalar_from = 4 * groups;
  }
  for (std::size_t i = scalar_from + thread; i < n; i += threads)
    widen(lo, hi, __ldg(xyz + 3 * i), __ldg(xyz + 3 * i + 1), __ldg(xyz + 3 * i + 2));

  float v[6];
  block_reduce(lo, hi, v);
  if (threadIdx.x == 0) {
    for (int k = 0; k < 6; ++k) partials[6 * blockIdx.x + k] = v[k];
    __threadfence();
    last = atomicAdd(counter, 1u) == gridDim.x - 1;
  }
  __syncthreads();
  if (!last) return;
  __threadfence();
  // The last block reduces the partials of all blocks, all its threads together.
  float l[3] = {FLT_MAX, FLT_MAX, FLT_MAX}, h[3] = {-FLT_MAX, -FLT_MAX, -FLT_MAX};
  for (unsigned b = threadIdx.x; b < gridDim.x; b += bbox_block) {
    const float* p = partials + 6 * b;
    widen(l, h, __ldcg(p), __ldcg(p + 1), __ldcg(p + 2));
    widen(l, h, __ldcg(p + 3), __ldcg(p + 4), __ldcg(p + 5));
  }
  block_reduce(l, h, v);
  if (threadIdx.x == 0) {
    for (int a = 0; a < 3; ++a) result->lo[a] = v[a], result->hi[a] = v[3 + a];
    *counter = 0;  // ready for the next call
    __threadfence_system();
    *static_cast<volatile unsigned*>(&result->sequence) = sequence;  // the box is there
    __threadfence_system();
  }
}

}  // namespace

BoundingBox::~BoundingBox() {
  if (result_) cudaFreeHost(result_);
}

void BoundingBox::compute(const float* xyz, std::size_t n, float lo[3], float hi[3],
                          cudaStream_t stream) {
  if (!result_) {
    RAYCUT_CUDA_CHECK(
        cudaHostAlloc(reinterpret_cast<void**>(&result_), sizeof(BoxResult), cudaHostAllocMapped));
    result_->sequence = sequence_;
    counter_.resize(1);
    RAYCUT_CUDA_CHECK(cudaMemset(counter_.data(), 0, sizeof(unsigned)));
    partials_.resize(6 * bbox_max_blocks);
    RAYCUT_CUDA_CHECK(
        cudaHostGetDevicePointer(reinterpret_cast<void**>(&device_result_), result_, 0));
  }
  const unsigned sequence = ++sequence_;
  const int blocks = static_cast<int>(std::max<std::size_t>(
      1, std::min<std::size_t>((n / 4 + bbox_block - 1) / bbox_block, bbox_max_blocks)));
  bounding_box_kernel<<<blocks, bbox_block, 0, stream>>>(xyz, n, partials_.data(), counter_.data(),
                                                         device_result_, sequence);
  RAYCUT_CUDA_CHECK_LAUNCH();
  // Poll the sequence number the kernel writes last; every few thousand polls ask the stream, so
  // that a failed kernel raises its error instead of leaving us spinning.
  const volatile unsigned* written = &result_->sequence;
  for (unsigned polls = 1; *written != sequence; ++polls) {
    if (polls % 4096 != 0) continue;
    const cudaError_t status = cudaStreamQuery(stream);
    if (status == cudaErrorNotReady) continue;
    RAYCUT_CUDA_CHECK(status);
    if (*written != sequence)
      throw Error(ErrorCode::internal, "the bounding-box kernel finished without its result");
  }
  std::atomic_thread_fence(std::memory_order_acquire);
  for (int a = 0; a < 3; ++a) {
    lo[a] = result_->lo[a];
    hi[a] = result_->hi[a];
  }
}

}  // namespace raycut::detail::cuda
