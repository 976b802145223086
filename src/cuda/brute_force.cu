// The oracle on the GPU: every target against every source, sources staged through shared
// memory in tiles. O(N^2): for tests and small inputs.
#include "cuda/device_results.cuh"
#include "cuda/methods.hpp"
#include "raycut/predicate.hpp"

namespace raycut::detail::cuda {
namespace {

constexpr int block_size = 256;

// Calls on_pair(j, dx, dy, dz, r2) for every in-range source j of the thread's target.
template <class OnPair>
__device__ void for_each_pair(const float* xyz, std::size_t n, float cutoff_squared, std::size_t i,
                              OnPair&& on_pair) {
  __shared__ float tile[3 * block_size];
  const bool active = i < n;
  const float xi = active ? xyz[3 * i] : 0, yi = active ? xyz[3 * i + 1] : 0,
              zi = active ? xyz[3 * i + 2] : 0;
  for (std::size_t base = 0; base < n; base += block_size) {
    const std::size_t load = base + threadIdx.x;
    __syncthreads();
    if (load < n) {
      tile[3 * threadIdx.x] = xyz[3 * load];
      tile[3 * threadIdx.x + 1] = xyz[3 * load + 1];
      tile[3 * threadIdx.x + 2] = xyz[3 * load + 2];
    }
    __syncthreads();
    const int count = n - base < block_size ? static_cast<int>(n - base) : block_size;
    if (!active) continue;
    for (int t = 0; t < count; ++t) {
      const std::size_t j = base + t;
      if (j == i) continue;
      const float dx = tile[3 * t] - xi, dy = tile[3 * t + 1] - yi, dz = tile[3 * t + 2] - zi;
      const float r2 = squared_distance(dx, dy, dz);
      if (in_range(r2, cutoff_squared)) on_pair(j, dx, dy, dz, r2);
    }
  }
}

template <class K>
__global__ void compute_kernel(const float* xyz, std::size_t n, float cutoff_squared, K kernel,
                               OutputView out) {
  const std::size_t i = blockIdx.x * std::size_t{block_size} + threadIdx.x;
  Accumulator acc;
  for_each_pair(
      xyz, n, cutoff_squared, i, [&](std::size_t j, float dx, float dy, float dz, float r2) {
        kernel(acc, static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j), dx, dy, dz, r2);
      });
  if (i < n) out.store(i, acc, kernel);
}

__global__ void count_kernel(const float* xyz, std::size_t n, float cutoff_squared,
                             std::uint32_t* counts) {
  const std::size_t i = blockIdx.x * std::size_t{block_size} + threadIdx.x;
  std::uint32_t c = 0;
  for_each_pair(xyz, n, cutoff_squared, i, [&](std::size_t, float, float, float, float) { ++c; });
  if (i < n) counts[i] = c;
}

__global__ void fill_kernel(const float* xyz, std::size_t n, float cutoff_squared,
                            const std::uint64_t* offsets, std::uint32_t* indices) {
  const std::size_t i = blockIdx.x * std::size_t{block_size} + threadIdx.x;
  std::uint64_t slot = i < n ? offsets[i] : 0;
  for_each_pair(xyz, n, cutoff_squared, i, [&](std::size_t j, float, float, float, float) {
    indices[slot++] = static_cast<std::uint32_t>(j);
  });
}

class BruteForceGpu final : public GpuMethod {
 public:
  void build(const float* xyz, std::size_t n, float cutoff) override {
    build_timer_.start();
    xyz_.resize(3 * n);
    RAYCUT_CUDA_CHECK(
        cudaMemcpyAsync(xyz_.data(), xyz, 3 * n * sizeof(float), cudaMemcpyDeviceToDevice));
    build_timer_.stop();
    n_ = n;
    cutoff_squared_ = squared_cutoff(cutoff);
  }

  void compute(Kernel kernel, const KernelOptions& options) override {
    timed_compute(kernel, n_, [&](const OutputView& out) {
      with_kernel(kernel, options, cutoff_squared_, [&](auto k) {
        compute_kernel<<<blocks(), block_size>>>(xyz_.data(), n_, cutoff_squared_, k, out);
      });
    });
  }

  NeighbourList neighbours() override {
    return build_neighbour_list(
        n_,
        [&](std::uint32_t* counts) {
          count_kernel<<<blocks(), block_size>>>(xyz_.data(), n_, cutoff_squared_, counts);
          RAYCUT_CUDA_CHECK_LAUNCH();
        },
        [&](const std::uint64_t* offsets, std::uint32_t* indices) {
          fill_kernel<<<blocks(), block_size>>>(xyz_.data(), n_, cutoff_squared_, offsets, indices);
          RAYCUT_CUDA_CHECK_LAUNCH();
        });
  }

 private:
  unsigned blocks() const { return static_cast<unsigned>((n_ + block_size - 1) / block_size); }

  DeviceBuffer<float> xyz_;
  std::size_t n_ = 0;
  float cutoff_squared_ = 0;
};

}  // namespace

std::unique_ptr<Method> make_brute_force() {
  return std::make_unique<BruteForceGpu>();
}

}  // namespace raycut::detail::cuda
