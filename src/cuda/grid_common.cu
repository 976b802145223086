#include <cub/block/block_reduce.cuh>

#include <algorithm>
#include <cfloat>

#include "cuda/grid_common.cuh"

namespace raycut::detail::cuda {
namespace {

// 3 x 128 threads: with a stride that is a multiple of 3, each thread reads one axis only, and
// a warp reads 32 consecutive floats.
constexpr int bbox_block = 384;
constexpr int bbox_max_blocks = 264;  // two per SM of an H100: enough to stream the positions

struct Min {
  __device__ float operator()(float a, float b) const { return fminf(a, b); }
};
struct Max {
  __device__ float operator()(float a, float b) const { return fmaxf(a, b); }
};

__global__ void __launch_bounds__(bbox_block)
    bounding_box_kernel(const float* xyz, std::size_t count, float* partials, unsigned* counter,
                        float* result) {
  using Reduce = cub::BlockReduce<float, bbox_block>;
  __shared__ typename Reduce::TempStorage temp;
  __shared__ float block_value[6];
  __shared__ bool last;

  const std::size_t first = blockIdx.x * std::size_t{bbox_block} + threadIdx.x;
  const std::size_t stride = std::size_t{gridDim.x} * bbox_block;
  const int axis = static_cast<int>(first % 3);  // stride % 3 == 0: fixed per thread
  float lo = FLT_MAX, hi = -FLT_MAX;
  // Unrolled so that U independent loads are in flight per thread (a few per thread in all).
  constexpr int U = 4;
  for (std::size_t e = first; e < count; e += U * stride) {
    float v[U];
#pragma unroll
    for (int u = 0; u < U; ++u)
      v[u] = e + u * stride < count ? __ldg(&xyz[e + u * stride]) : xyz[e];
#pragma unroll
    for (int u = 0; u < U; ++u) {
      lo = fminf(lo, v[u]);
      hi = fmaxf(hi, v[u]);
    }
  }
  for (int a = 0; a < 3; ++a) {
    const float mine_lo = a == axis ? lo : FLT_MAX;
    const float mine_hi = a == axis ? hi : -FLT_MAX;
    const float block_lo = Reduce(temp).Reduce(mine_lo, Min{});
    __syncthreads();
    const float block_hi = Reduce(temp).Reduce(mine_hi, Max{});
    __syncthreads();
    if (threadIdx.x == 0) {
      block_value[a] = block_lo;
      block_value[3 + a] = block_hi;
    }
  }
  __syncthreads();
  if (threadIdx.x < 6) partials[6 * blockIdx.x + threadIdx.x] = block_value[threadIdx.x];
  __threadfence();
  __syncthreads();
  if (threadIdx.x == 0) last = atomicAdd(counter, 1u) == gridDim.x - 1;
  __syncthreads();
  if (!last) return;
  __threadfence();
  // The last block reduces the partials of all blocks, all its threads together.
  for (int k = 0; k < 6; ++k) {
    const bool is_lo = k < 3;
    float v = is_lo ? FLT_MAX : -FLT_MAX;
    for (unsigned b = threadIdx.x; b < gridDim.x; b += bbox_block) {
      const float q = __ldcg(&partials[6 * b + k]);
      v = is_lo ? fminf(v, q) : fmaxf(v, q);
    }
    const float r = is_lo ? Reduce(temp).Reduce(v, Min{}) : Reduce(temp).Reduce(v, Max{});
    __syncthreads();
    if (threadIdx.x == 0) result[k] = r;
  }
  if (threadIdx.x == 0) *counter = 0;  // ready for the next call
  __threadfence_system();
}

}  // namespace

BoundingBox::~BoundingBox() {
  if (result_) cudaFreeHost(result_);
}

void BoundingBox::compute(const float* xyz, std::size_t n, float lo[3], float hi[3],
                          cudaStream_t stream) {
  if (!result_) {
    RAYCUT_CUDA_CHECK(
        cudaHostAlloc(reinterpret_cast<void**>(&result_), 6 * sizeof(float), cudaHostAllocMapped));
    counter_.resize(1);
    RAYCUT_CUDA_CHECK(cudaMemset(counter_.data(), 0, sizeof(unsigned)));
    partials_.resize(6 * bbox_max_blocks);
    RAYCUT_CUDA_CHECK(
        cudaHostGetDevicePointer(reinterpret_cast<void**>(&device_result_), result_, 0));
  }
  const std::size_t count = 3 * n;
  const int blocks = static_cast<int>(
      std::min<std::size_t>((count + bbox_block - 1) / bbox_block, bbox_max_blocks));
  bounding_box_kernel<<<blocks, bbox_block, 0, stream>>>(xyz, count, partials_.data(),
                                                         counter_.data(), device_result_);
  RAYCUT_CUDA_CHECK_LAUNCH();
  RAYCUT_CUDA_CHECK(cudaStreamSynchronize(stream));
  for (int a = 0; a < 3; ++a) {
    lo[a] = result_[a];
    hi[a] = result_[3 + a];
  }
}

}  // namespace raycut::detail::cuda
