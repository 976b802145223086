// The oracle on the GPU: every target against every source, sources staged through shared
// memory in tiles. O(N^2): for tests and small inputs. nvcc only.
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>

#include "raycut/detail/cuda/visit.cuh"
#include "raycut/detail/pair_pass.hpp"

namespace raycut::detail::cuda {

constexpr int brute_force_block_size = 256;

// Targets are points [0, n), sources every point [0, points) of the same system (batches).
template <class F, class Images>
__global__ void brute_force_kernel(const float* xyz, std::size_t n, std::size_t points,
                                   const std::uint32_t* system, float cutoff_squared, F f,
                                   Images images) {
  __shared__ float tile[3 * brute_force_block_size];
  const std::size_t i = blockIdx.x * std::size_t{brute_force_block_size} + threadIdx.x;
  const bool active = i < n;
  const float xi = active ? xyz[3 * i] : 0, yi = active ? xyz[3 * i + 1] : 0,
              zi = active ? xyz[3 * i + 2] : 0;
  const std::uint32_t si = active && system ? system[i] : 0;
  const auto ii = static_cast<std::uint32_t>(i);
  const typename Images::Target ti = active ? images.target(ii) : typename Images::Target{};
  typename F::Accumulator acc{};
  if (active) acc = initial_state(f, ii);
  for (std::size_t base = 0; base < points; base += brute_force_block_size) {
    const std::size_t load = base + threadIdx.x;
    __syncthreads();
    if (load < points) {
      tile[3 * threadIdx.x] = xyz[3 * load];
      tile[3 * threadIdx.x + 1] = xyz[3 * load + 1];
      tile[3 * threadIdx.x + 2] = xyz[3 * load + 2];
    }
    __syncthreads();
    const int count = points - base < brute_force_block_size ? static_cast<int>(points - base)
                                                             : brute_force_block_size;
    if (!active) continue;
    for (int t = 0; t < count; ++t) {
      const std::size_t j = base + t;
      if (j == i || (system && system[j] != si)) continue;
      Vec3 r{tile[3 * t] - xi, tile[3 * t + 1] - yi, tile[3 * t + 2] - zi};
      float r2 = squared_distance(r.x, r.y, r.z);
      const auto k = static_cast<std::uint32_t>(j);
      const bool in = in_range_of(images, cutoff_squared, ii, k, r, r2);
      visit(f, acc, in, ii, k, k, r, r2, images, ti);
    }
  }
  if (active) f.finish(ii, acc);
}

template <class F>
void run_brute_force(const PairPass& pass, const F& f, cudaStream_t stream) {
  with_images<F>(
      pass,
      [&](const auto& images) {
        brute_force_kernel<<<blocks_for(pass.n, brute_force_block_size), brute_force_block_size, 0,
                             stream>>>(pass.brute_force.xyz, pass.n, pass.points,
                                       pass.brute_force.system, pass.cutoff_squared, f, images);
      },
      stream);
  RAYCUT_CUDA_CHECK_LAUNCH();
}

}  // namespace raycut::detail::cuda
