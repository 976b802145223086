// grid-paper: the seed paper's CUDA grid (Cuda-version/cudaLJ.cu), kept for comparison. A dense
// grid of cells at least C wide over the bounding box; particles are counted per cell with
// atomics, a prefix sum gives each cell's first slot, and a second atomic pass scatters them into
// cell order (so the order inside a cell varies from run to run). Each target then scans the 27
// cells around its own. The dense grid needs memory for every cell of the box, so it is checked
// against free device memory before anything is allocated.
#include <cub/device/device_scan.cuh>

#include <cstdint>
#include <string>

#include "cuda/device_results.cuh"
#include "cuda/grid_common.cuh"
#include "cuda/methods.hpp"
#include "raycut/detail/cell_grid.hpp"
#include "raycut/detail/cuda/grid_paper_pass.cuh"
#include "raycut/predicate.hpp"

namespace raycut::detail::cuda {
namespace {

__global__ void count_per_cell(const float* xyz, std::uint32_t n, CellGrid grid,
                               std::uint32_t* counts) {
  const std::uint32_t i = blockIdx.x * paper_block_size + threadIdx.x;
  if (i >= n) return;
  atomicAdd(&counts[grid.key_of(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2])], 1u);
}

__global__ void scatter_to_cells(const float* xyz, std::uint32_t n, CellGrid grid,
                                 const std::uint32_t* start, std::uint32_t* tickets, float* x,
                                 float* y, float* z, std::uint32_t* index) {
  const std::uint32_t i = blockIdx.x * paper_block_size + threadIdx.x;
  if (i >= n) return;
  const float px = xyz[3 * i], py = xyz[3 * i + 1], pz = xyz[3 * i + 2];
  const std::uint64_t key = grid.key_of(px, py, pz);
  const std::uint32_t slot = start[key] + atomicAdd(&tickets[key], 1u);
  x[slot] = px;
  y[slot] = py;
  z[slot] = pz;
  index[slot] = i;
}

class GridPaper final : public CudaPairMethod<GridPaper> {
 public:
  std::string points_unsupported() const override {
    return "grid-paper reproduces the paper's grid over one open box (use grid)";
  }
  void build(const float* xyz, std::size_t n, float cutoff) override {
    if (n >= UINT32_MAX)
      throw Error(ErrorCode::invalid_argument,
                  "grid-paper handles at most 2^32 - 2 particles, got " + std::to_string(n));
    n_ = static_cast<std::uint32_t>(n);
    cutoff_squared_ = squared_cutoff(cutoff);
    build_timer_.start(stream_);
    float lo[3], hi[3];
    box_.compute(xyz, n, lo, hi, stream_);
    grid_ = make_cell_grid(lo, hi, cutoff);
    const std::uint64_t cells = grid_.cell_count();
    reserve(cells);

    // Count per cell, prefix sum, scatter with a ticket per cell (the paper's three loops).
    const std::size_t table = static_cast<std::size_t>(cells) + 1;
    RAYCUT_CUDA_CHECK(cudaMemsetAsync(counts_.data(), 0, table * sizeof(std::uint32_t), stream_));
    count_per_cell<<<blocks(), paper_block_size, 0, stream_>>>(xyz, n_, grid_, counts_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    std::size_t temp_bytes = 0;
    RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, counts_.data(),
                                                    start_.data(), std::int64_t(table), stream_));
    temp_.resize(temp_bytes);
    RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(temp_.data(), temp_bytes, counts_.data(),
                                                    start_.data(), std::int64_t(table), stream_));
    RAYCUT_CUDA_CHECK(cudaMemsetAsync(counts_.data(), 0, table * sizeof(std::uint32_t), stream_));
    scatter_to_cells<<<blocks(), paper_block_size, 0, stream_>>>(
        xyz, n_, grid_, start_.data(), counts_.data(), x_.data(), y_.data(), z_.data(),
        index_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    build_timer_.stop(stream_);
  }

  std::size_t size() const { return n_; }
  PairPass pair_pass() const override {
    PairPass pass;
    pass.kind = PassKind::grid_paper;
    pass.n = n_;
    pass.cutoff_squared = cutoff_squared_;
    pass.grid_paper = {x_.data(), y_.data(), z_.data(), index_.data(), start_.data(), grid_};
    return pass;
  }
  template <class F>
  void run(const F& f) const {
    run_grid_paper(pair_pass(), f, stream_);
  }

 private:
  unsigned blocks() const { return blocks_for(n_, paper_block_size); }

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
