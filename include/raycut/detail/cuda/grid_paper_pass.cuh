// The seed paper's traversal (Cuda-version/cudaLJ.cu): each target scans the 27 cells around its
// own in a dense grid of cells at least C wide (built by src/cuda/grid_paper.cu). Kept for
// comparison (no periodic images, batches or query points); every functor runs through
// run_grid_paper(). nvcc only.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "raycut/detail/cuda/visit.cuh"
#include "raycut/detail/pair_pass.hpp"

namespace raycut::detail::cuda {

constexpr int paper_block_size = 128;  // the paper's block size

template <class F>
__global__ void grid_paper_kernel(GridPaperPass p, std::uint32_t n, float cutoff_squared, F f) {
  const std::uint32_t t = blockIdx.x * paper_block_size + threadIdx.x;
  if (t >= n) return;
  const CellGrid& grid = p.grid;
  const float xt = p.x[t], yt = p.y[t], zt = p.z[t];
  const std::uint32_t i = p.index[t];
  typename F::Accumulator acc = initial_state(f, i);
  const std::int64_t cx = grid.coord(xt, 0), cy = grid.coord(yt, 1), cz = grid.coord(zt, 2);
  const std::int64_t last_x = grid.dims[0] - 1, last_y = grid.dims[1] - 1,
                     last_z = grid.dims[2] - 1;
  for (std::int64_t iz = cz > 0 ? cz - 1 : 0; iz <= (cz < last_z ? cz + 1 : last_z); ++iz) {
    for (std::int64_t iy = cy > 0 ? cy - 1 : 0; iy <= (cy < last_y ? cy + 1 : last_y); ++iy) {
      for (std::int64_t ix = cx > 0 ? cx - 1 : 0; ix <= (cx < last_x ? cx + 1 : last_x); ++ix) {
        const std::uint64_t key =
            grid.key(static_cast<std::uint32_t>(ix), static_cast<std::uint32_t>(iy),
                     static_cast<std::uint32_t>(iz));
        const std::uint32_t end = p.start[key + 1];
        for (std::uint32_t s = p.start[key]; s < end; ++s) {
          if (s == t) continue;
          const Vec3 r{p.x[s] - xt, p.y[s] - yt, p.z[s] - zt};
          const float r2 = squared_distance(r.x, r.y, r.z);
          visit(f, acc, in_range(r2, cutoff_squared), i, p.index[s], s, r, r2, NoImages{}, {});
        }
      }
    }
  }
  f.finish(i, acc);
}

template <class F>
void run_grid_paper(const PairPass& pass, const F& f, cudaStream_t stream) {
  const auto n = static_cast<std::uint32_t>(pass.n);
  grid_paper_kernel<<<blocks_for(n, paper_block_size), paper_block_size, 0, stream>>>(
      pass.grid_paper, n, pass.cutoff_squared, f);
  RAYCUT_CUDA_CHECK_LAUNCH();
}

}  // namespace raycut::detail::cuda
