// grid-paper: the seed paper's CUDA grid (Cuda-version/cudaLJ.cu), kept for comparison. A dense
// grid of cells at least C wide over the bounding box; particles are counted per cell with
// atomics, a prefix sum gives each cell's first slot, and a second atomic pass scatters them into
// cell order (so the order inside a cell varies from run to run). Each target then scans the 27
// cells around its own. The dense grid needs memory for every cell of the box, so it is checked
// against free device memory before anything is allocated.
#include <cub/device/device_scan.cuh>

#include <cstdint>
#include <string>

#include "core/cell_grid.hpp"
#include "cuda/device_results.cuh"
#include "cuda/grid_common.cuh"
#include "cuda/methods.hpp"
#include "raycut/predicate.hpp"

namespace raycut::detail::cuda {
namespace {

constexpr int paper_block = 128;  // the paper's block size

// Particles in cell order, one array per coordinate as in the paper.
struct SortedParticles {
  const float* x;
  const float* y;
  const float* z;
  const std::uint32_t* index;  // original index
};

__global__ void count_per_cell(const float* xyz, std::uint32_t n, CellGrid grid,
                               std::uint32_t* counts) {
  const std::uint32_t i = blockIdx.x * paper_block + threadIdx.x;
  if (i >= n) return;
  atomicAdd(&counts[grid.key_of(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2])], 1u);
}

__global__ void scatter_to_cells(const float* xyz, std::uint32_t n, CellGrid grid,
                                 const std::uint32_t* start, std::uint32_t* tickets, float* x,
                                 float* y, float* z, std::uint32_t* index) {
  const std::uint32_t i = blockIdx.x * paper_block + threadIdx.x;
  if (i >= n) return;
  const float px = xyz[3 * i], py = xyz[3 * i + 1], pz = xyz[3 * i + 2];
  const std::uint64_t key = grid.key_of(px, py, pz);
  const std::uint32_t slot = start[key] + atomicAdd(&tickets[key], 1u);
  x[slot] = px;
  y[slot] = py;
  z[slot] = pz;
  index[slot] = i;
}

// Calls on_pair(j, dx, dy, dz, r2) for every in-range source j of the target in slot t.
template <class OnPair>
__device__ __forceinline__ void for_each_pair(const SortedParticles& p, const CellGrid& grid,
                                              const std::uint32_t* start, float cutoff_squared,
                                              std::uint32_t t, OnPair&& on_pair) {
  const float xt = p.x[t], yt = p.y[t], zt = p.z[t];
  const std::int64_t cx = grid.coord(xt, 0), cy = grid.coord(yt, 1), cz = grid.coord(zt, 2);
  const std::int64_t last_x = grid.dims[0] - 1, last_y = grid.dims[1] - 1,
                     last_z = grid.dims[2] - 1;
  for (std::int64_t iz = cz > 0 ? cz - 1 : 0; iz <= (cz < last_z ? cz + 1 : last_z); ++iz) {
    for (std::int64_t iy = cy > 0 ? cy - 1 : 0; iy <= (cy < last_y ? cy + 1 : last_y); ++iy) {
      for (std::int64_t ix = cx > 0 ? cx - 1 : 0; ix <= (cx < last_x ? cx + 1 : last_x); ++ix) {
        const std::uint64_t key =
            grid.key(static_cast<std::uint32_t>(ix), static_cast<std::uint32_t>(iy),
                     static_cast<std::uint32_t>(iz));
        const std::uint32_t end = start[key + 1];
        for (std::uint32_t s = start[key]; s < end; ++s) {
          if (s == t) continue;
          const float dx = p.x[s] - xt, dy = p.y[s] - yt, dz = p.z[s] - zt;
          const float r2 = squared_distance(dx, dy, dz);
          if (in_range(r2, cutoff_squared)) on_pair(s, dx, dy, dz, r2);
        }
      }
    }
  }
}

template <class K>
__global__ void compute_kernel(SortedParticles p, std::uint32_t n, CellGrid grid,
                               const std::uint32_t* start, float cutoff_squared, K kernel,
                               OutputView out) {
  const std::uint32_t t = blockIdx.x * paper_block + threadIdx.x;
  if (t >= n) return;
  Accumulator acc;
  const std::uint32_t i = p.index[t];
  for_each_pair(p, grid, start, cutoff_squared, t,
                [&](std::uint32_t s, float dx, float dy, float dz, float r2) {
                  kernel(acc, i, p.index[s], dx, dy, dz, r2);
                });
  out.store(i, acc, kernel);
}

__global__ void count_kernel(SortedParticles p, std::uint32_t n, CellGrid grid,
                             const std::uint32_t* start, float cutoff_squared,
                             std::uint32_t* counts) {
  const std::uint32_t t = blockIdx.x * paper_block + threadIdx.x;
  if (t >= n) return;
  std::uint32_t c = 0;
  for_each_pair(p, grid, start, cutoff_squared, t,
                [&](std::uint32_t, float, float, float, float) { ++c; });
  counts[p.index[t]] = c;
}

__global__ void fill_kernel(SortedParticles p, std::uint32_t n, CellGrid grid,
                            const std::uint32_t* start, float cutoff_squared,
                            const std::uint64_t* offsets, std::uint32_t* indices) {
  const std::uint32_t t = blockIdx.x * paper_block + threadIdx.x;
  if (t >= n) return;
  std::uint64_t slot = offsets[p.index[t]];
  for_each_pair(p, grid, start, cutoff_squared, t,
                [&](std::uint32_t s, float, float, float, float) { indices[slot++] = p.index[s]; });
}

class GridPaper final : public GpuMethod {
 public:
  void build(const float* xyz, std::size_t n, float cutoff) override {
    if (n >= UINT32_MAX)
      throw Error(ErrorCode::invalid_argument,
                  "grid-paper handles at most 2^32 - 2 particles, got " + std::to_string(n));
    n_ = static_cast<std::uint32_t>(n);
    cutoff_squared_ = squared_cutoff(cutoff);
    build_timer_.start();
    float lo[3], hi[3];
    box_.compute(xyz, n, lo, hi);
    grid_ = make_cell_grid(lo, hi, cutoff);
    const std::uint64_t cells = grid_.cell_count();
    reserve(cells);

    // Count per cell, prefix sum, scatter with a ticket per cell (the paper's three loops).
    const std::size_t table = static_cast<std::size_t>(cells) + 1;
    RAYCUT_CUDA_CHECK(cudaMemsetAsync(counts_.data(), 0, table * sizeof(std::uint32_t)));
    count_per_cell<<<blocks(), paper_block>>>(xyz, n_, grid_, counts_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    std::size_t temp_bytes = 0;
    RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, counts_.data(),
                                                    start_.data(), std::int64_t(table)));
    temp_.resize(temp_bytes);
    RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(temp_.data(), temp_bytes, counts_.data(),
                                                    start_.data(), std::int64_t(table)));
    RAYCUT_CUDA_CHECK(cudaMemsetAsync(counts_.data(), 0, table * sizeof(std::uint32_t)));
    scatter_to_cells<<<blocks(), paper_block>>>(xyz, n_, grid_, start_.data(), counts_.data(),
                                                x_.data(), y_.data(), z_.data(), index_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    build_timer_.stop();
  }

  void compute(Kernel kernel, const KernelOptions& options) override {
    timed_compute(kernel, n_, [&](const OutputView& out) {
      with_kernel(kernel, options, cutoff_squared_, [&](auto k) {
        compute_kernel<<<blocks(), paper_block>>>(sorted(), n_, grid_, start_.data(),
                                                  cutoff_squared_, k, out);
      });
    });
  }

  NeighbourList neighbours() override {
    return build_neighbour_list(
        n_,
        [&](std::uint32_t* counts) {
          count_kernel<<<blocks(), paper_block>>>(sorted(), n_, grid_, start_.data(),
                                                  cutoff_squared_, counts);
          RAYCUT_CUDA_CHECK_LAUNCH();
        },
        [&](const std::uint64_t* offsets, std::uint32_t* indices) {
          fill_kernel<<<blocks(), paper_block>>>(sorted(), n_, grid_, start_.data(),
                                                 cutoff_squared_, offsets, indices);
          RAYCUT_CUDA_CHECK_LAUNCH();
        });
  }

 private:
  unsigned blocks() const { return (n_ + paper_block - 1) / paper_block; }
  SortedParticles sorted() const { return {x_.data(), y_.data(), z_.data(), index_.data()}; }

  // The dense grid's memory, checked against free memory before any allocation.
  void reserve(std::uint64_t cells) {
    const double table_bytes = 2.0 * (static_cast<double>(cells) + 1) * sizeof(std::uint32_t);
    const double particle_bytes = 16.0 * n_;
    const double held = static_cast<double>(counts_.bytes() + start_.bytes() + x_.bytes() +
                                            y_.bytes() + z_.bytes() + index_.bytes());
    const double need = table_bytes + particle_bytes;
    if (need > held) {
      const double extra = need - held;
      const std::string what = "grid-paper's dense grid of " + std::to_string(grid_.dims[0]) +
                               " x " + std::to_string(grid_.dims[1]) + " x " +
                               std::to_string(grid_.dims[2]) + " = " + std::to_string(cells) +
                               " cells (" + format_bytes(table_bytes) +
                               ") plus the sorted particles (" + format_bytes(particle_bytes) + ")";
      if (extra >= 9.0e18)  // beyond any device: do not even ask
        throw Error(ErrorCode::out_of_memory, "not enough device memory for " + what);
      require_device_memory(static_cast<std::size_t>(extra), what.c_str());
    }
    const std::size_t table = static_cast<std::size_t>(cells) + 1;
    counts_.resize(table);
    start_.resize(table);
    x_.resize(n_);
    y_.resize(n_);
    z_.resize(n_);
    index_.resize(n_);
  }

  std::uint32_t n_ = 0;
  float cutoff_squared_ = 0;
  CellGrid grid_;
  BoundingBox box_;
  DeviceBuffer<std::uint32_t> counts_, start_, index_;
  DeviceBuffer<float> x_, y_, z_;
  DeviceBuffer<unsigned char> temp_;
};

}  // namespace

std::unique_ptr<Method> make_grid_paper() {
  return std::make_unique<GridPaper>();
}

}  // namespace raycut::detail::cuda
