// The production grid's tables (docs/grid.md): the particles in cell order as float4 (w = the
// caller's index; within a cell by index, so every sum is the same on every run), and a table
// from cells to slots:
//   dense   start[c] for every cell c (+1 entry): a counting sort (by particle, by cell, or in
//           one block), or a radix sort with run ends and a prefix maximum;
//   compact the sorted unique cell keys with their first slots, and a hash table from row
//           (y, z) to that row's run of unique cells (a far outlier, a sphere surface at fine
//           cells): memory O(N) whatever the distribution.
// Which one, and how, is decided by plan_grid (grid_policy.hpp); the traversal that reads them is
// include/raycut/detail/cuda/grid_pass.cuh.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "cuda/device_buffer.cuh"
#include "cuda/device_results.cuh"
#include "cuda/grid_policy.hpp"

namespace raycut::detail::cuda {

class GridTables {
 public:
  // Builds what `plan` asks for over n device positions, queued on `stream` (the compact table
  // reads its number of cells back).
  void build(const float* xyz, std::uint32_t n, const GridPlan& plan, cudaStream_t stream);
  // The slots of points [0, targets) in slot order, for a pass over those targets only.
  void select_targets(std::uint32_t targets, cudaStream_t stream);
  // The image of each slot's point (image[point], gathered into slot order: the traversal's
  // candidates of a row then read consecutive entries).
  void gather_images(const PointImage* image, cudaStream_t stream);
  const PointImage* slot_images() const { return slot_images_.data(); }
  // The traversal's view of the last build.
  GridPass pass(const GridPlan& plan) const;

 private:
  void build_dense(const float* xyz, const GridPlan& plan, cudaStream_t stream);
  void build_compact(const float* xyz, const GridPlan& plan, cudaStream_t stream);
  template <class Key>
  void sort(DeviceBuffer<Key>& keys, DeviceBuffer<Key>& keys_alt, int bits, Key*& sorted_keys,
            cudaStream_t stream);
  template <class Op>
  void scan(Op op, std::uint64_t count, bool exclusive, cudaStream_t stream);

  std::uint32_t n_ = 0;
  DeviceBuffer<std::uint32_t> keys32_, keys32_alt_;
  DeviceBuffer<std::uint64_t> keys64_, keys64_alt_;
  DeviceBuffer<std::uint32_t> index_, index_alt_, run_start_;
  std::uint32_t* order_ = nullptr;  // index_ or index_alt_: sorted slot -> original index
  DeviceBuffer<float4> pos_;
  DeviceBuffer<std::uint32_t> targets_;   // select_targets()
  DeviceBuffer<PointImage> slot_images_;  // gather_images()
  DeviceBuffer<std::uint32_t> selected_;  // its count (device; the number is known)
  DeviceBuffer<std::uint32_t> start_;     // dense: per cell; compact: per non-empty cell
  DeviceBuffer<std::uint64_t> cell_keys_, row_keys_;
  DeviceBuffer<uint2> row_cells_;
  std::uint64_t row_mask_ = 0;
  int row_shift_ = 0;
  MappedValue<std::uint32_t> runs_;  // the compact table's number of non-empty cells
  DeviceBuffer<unsigned char> temp_;
  std::uint64_t sort_shape_ = 0, scan_shape_ = 0;
  std::size_t sort_temp_bytes_ = 0, scan_temp_bytes_ = 0;
};

}  // namespace raycut::detail::cuda
