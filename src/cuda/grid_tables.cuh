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
#include <mutex>

#include "cuda/device_buffer.cuh"
#include "cuda/device_results.cuh"
#include "cuda/grid_policy.hpp"

namespace raycut::detail::cuda {

// The image of each slot's point (image[point] gathered into slot order: a row's candidates then
// read consecutive entries), gathered by the first pass after a build that reads images. Most
// kernels never do (count, lj_forces, sph: with_images), and the gather was 15 % of a periodic
// build (docs/periodic.md). Passes on other streams wait for the gather's event.
class SlotImages final : public DeferredImages {
 public:
  SlotImages() = default;
  ~SlotImages();
  SlotImages(const SlotImages&) = delete;
  SlotImages& operator=(const SlotImages&) = delete;
  // After a build: the point of each slot and the table by point.
  void reset(const std::uint32_t* order, std::uint32_t n, const PointImage* by_point);
  const PointImage* on(void* stream) const override;

 private:
  const std::uint32_t* order_ = nullptr;
  std::uint32_t n_ = 0;
  const PointImage* by_point_ = nullptr;
  mutable std::mutex mutex_;  // concurrent passes from host threads gather once
  mutable bool gathered_ = false;
  mutable cudaStream_t gathered_on_ = nullptr;
  mutable cudaEvent_t done_ = nullptr;
  mutable DeviceBuffer<PointImage> table_;
};

// A reused plan's box (Engine::set_reuse_plan): the first build kernel that reads a point outside
// [lo, hi] sets *misfit, if still 0, to count_plan_outgrown. Where the build reads each point
// anyway, one compare a coordinate instead of a bounding-box reduction of its own.
struct PlannedBox {
  float lo[3], hi[3];
  int* misfit = nullptr;  // null: nothing to watch
};

class GridTables {
 public:
  // Builds what `plan` asks for over n device positions, queued on `stream` (the compact table
  // reads its number of cells back); with `watch`, the points are checked against its box.
  void build(const float* xyz, std::uint32_t n, const GridPlan& plan, const PlannedBox& watch,
             cudaStream_t stream);
  // The slots of points [0, targets) in slot order, for a pass over those targets only.
  void select_targets(std::uint32_t targets, cudaStream_t stream);
  // The traversal's images by slot, from `by_point` (images of the last build's points),
  // gathered when a pass first reads them.
  const DeferredImages* slot_images(const PointImage* by_point);
  // The traversal's view of the last build.
  GridPass pass(const GridPlan& plan) const;

 private:
  void build_dense(const float* xyz, const GridPlan& plan, const PlannedBox& watch,
                   cudaStream_t stream);
  void build_compact(const float* xyz, const GridPlan& plan, const PlannedBox& watch,
                     cudaStream_t stream);
  template <class Key>
  void sort(DeviceBuffer<Key>& keys, DeviceBuffer<Key>& keys_alt, int bits, Key*& sorted_keys,
            cudaStream_t stream);
  void prefix_maximum(std::uint64_t count, cudaStream_t stream);

  std::uint32_t n_ = 0;
  DeviceBuffer<std::uint32_t> keys32_, keys32_alt_;
  DeviceBuffer<std::uint64_t> keys64_, keys64_alt_;
  DeviceBuffer<std::uint32_t> index_, index_alt_, run_start_;
  // index_ or index_alt_: the point (original index) of each slot, whatever sorted them.
  std::uint32_t* order_ = nullptr;
  DeviceBuffer<float4> pos_;
  DeviceBuffer<std::uint32_t> targets_;  // select_targets()
  SlotImages slot_images_;
  // GridPass::band_targets, made with slot_images_; scratch that every pass writes.
  mutable DeviceBuffer<std::uint32_t> band_targets_;
  DeviceBuffer<std::uint32_t> selected_;  // its count (device; the number is known)
  DeviceBuffer<std::uint32_t> start_;     // dense: per cell; compact: per non-empty cell
  DeviceBuffer<std::uint64_t> cell_keys_, row_keys_;
  DeviceBuffer<uint2> row_cells_;
  std::uint64_t row_mask_ = 0;
  int row_shift_ = 0;
  DeviceBuffer<std::uint32_t> runs_;  // the compact table's number of non-empty cells (device)
  DeviceBuffer<unsigned char> temp_;
  std::uint64_t sort_shape_ = 0, scan_shape_ = 0;
  std::size_t sort_temp_bytes_ = 0, scan_temp_bytes_ = 0;
};

}  // namespace raycut::detail::cuda
