// What every GPU method shares: per-target results on the device, the CUDA-event timers, the
// stream, and the neighbour lists (count pass, scan, fill pass: written once here for every
// CUDA and OptiX method, which only say how to run a functor over their pairs).
#pragma once

#include <cuda_runtime.h>

#include <cstdint>
#include <memory>
#include <vector>

#include "core/list_storage.hpp"
#include "core/method.hpp"
#include "cuda/device_buffer.cuh"
#include "raycut/detail/cuda/check.cuh"
#include "raycut/engine.hpp"
#include "raycut/kernels.hpp"

namespace raycut::detail::cuda {

class DeviceResults {
 public:
  // Sizes the buffers for `kernel` over n targets and returns where the kernel writes (every
  // target is written: nothing is cleared). The results are invalid until commit().
  KernelOutputs prepare(Kernel kernel, std::size_t n);
  void commit() { valid_ = true; }
  Results to_host() const;
  ResultsView view() const;

 private:
  Kernel kernel_ = Kernel::count;
  std::size_t n_ = 0;
  bool valid_ = false;
  // Pooled: take_results() hands them out, and the next run sizes new ones.
  PooledBuffer<std::uint32_t> count_;
  PooledBuffer<float> energy_, force_, virial_, density_;
};

// A pair of CUDA events around work queued on a stream.
class EventTimer {
 public:
  EventTimer();
  ~EventTimer();
  EventTimer(const EventTimer&) = delete;
  EventTimer& operator=(const EventTimer&) = delete;
  void start(cudaStream_t stream = nullptr);
  void stop(cudaStream_t stream = nullptr);
  // Waits for the stop event; negative when never started.
  double elapsed_ms() const;

 private:
  cudaEvent_t start_ = nullptr, stop_ = nullptr;
  bool started_ = false;
};

// A host value the device writes through mapped pinned memory (a count, a flag), read after the
// stream has reached it.
template <class T>
class MappedValue {
 public:
  MappedValue() {
    RAYCUT_CUDA_CHECK(
        cudaHostAlloc(reinterpret_cast<void**>(&host_), sizeof(T), cudaHostAllocMapped));
    RAYCUT_CUDA_CHECK(cudaHostGetDevicePointer(reinterpret_cast<void**>(&device_), host_, 0));
  }
  ~MappedValue() { cudaFreeHost(host_); }
  MappedValue(const MappedValue&) = delete;
  MappedValue& operator=(const MappedValue&) = delete;
  T* device() const { return device_; }
  T& host() { return *host_; }

 private:
  T* host_ = nullptr;
  T* device_ = nullptr;
};

// A CSR list in device memory; buffers only grow.
class DeviceListStorage final : public ListStorage {
 public:
  MemorySpace space() const override { return MemorySpace::device; }
  std::size_t bytes() const override;
  NeighbourList to_host() const override;
  void set_empty(const ListOptions& options) override;
  // Validated per-pair cutoffs (or null) as the pass reads them: uploaded into buffers kept
  // with the list, ordered on `stream`.
  PairCutoffFilter stage_cutoffs(const PairCutoffs* cutoffs, std::size_t n, void* stream);

  std::uint32_t* prepare_counts(std::size_t n, const ListOptions& options);
  // offsets = exclusive scan of the counts (offsets[n] = total), queued on `stream`.
  void scan(cudaStream_t stream);
  // scan(), then the total read back.
  std::uint64_t scan_counts(cudaStream_t stream);
  std::uint64_t* offsets_data() { return offsets_.data(); }
  ListFill prepare_fill(std::uint64_t pairs, const ListFilter& filter);

 private:
  void publish();
  // Pooled: a list is often made afresh per call (each Python call returns a new one).
  PooledBuffer<std::uint32_t> counts_;
  PooledBuffer<std::uint64_t> offsets_;
  PooledBuffer<std::uint32_t> indices_;
  PooledBuffer<float> distances_, vectors_;
  PooledBuffer<std::int32_t> shifts_;
  PooledBuffer<std::int64_t> rows_, columns_;  // ListOptions::coo
  PooledBuffer<unsigned char> scan_temp_;
  PooledBuffer<double> radii_, table_;  // ListOptions::cutoffs
  PooledBuffer<std::uint32_t> species_;
};

// A static-capacity list's end, queued on `stream`: the count from *total (device; null: 0),
// then padding from it (or from the capacity) to the capacity.
// `misfit` (or null): a nonzero value there is written as the count instead (a reused plan
// that no longer fits, Engine::set_reuse_plan).
void finish_static_pairs_on_device(const std::uint64_t* total, const StaticPairs& out,
                                   const int* misfit, cudaStream_t stream);

class DevicePaddedStorage final : public PaddedStorage {
 public:
  MemorySpace space() const override { return MemorySpace::device; }
  std::vector<std::uint32_t> indices_to_host() const override;
  std::vector<std::uint32_t> counts_to_host() const override;
  PaddedFill prepare(std::size_t n, std::uint32_t k, bool half, bool shifts, cudaStream_t stream);
  std::vector<std::int32_t> shifts_to_host() const override;
  // After the pass: the overflow into `report`.
  void read_report(cudaStream_t stream);

 private:
  PooledBuffer<std::uint32_t> indices_, counts_;
  PooledBuffer<std::int32_t> shifts_;
  // The kernel's atomics go to device memory (to mapped host memory they cost microseconds
  // each: 2.3x the whole padded pass at 1M particles); the report is copied back after.
  PooledBuffer<PaddedOverflow> overflow_;
};

// What every GPU method shares: positions and results on the device, the results kept until the
// next compute, the CUDA-event timers of build and compute, the stream, and the lists.
class GpuMethod : public Method {
 public:
  MemorySpace space() const override { return MemorySpace::device; }
  void set_stream(void* stream) override { stream_ = static_cast<cudaStream_t>(stream); }
  Results results() const override { return results_.to_host(); }
  ResultsView results_view() const override { return results_.view(); }
  OwnedResults take_results() override {
    auto owned = std::make_shared<DeviceResults>(std::move(results_));
    results_ = DeviceResults{};
    return {owned->view(), owned};
  }
  void synchronize() override { RAYCUT_CUDA_CHECK(cudaStreamSynchronize(stream_)); }
  double device_build_ms() const override { return build_timer_.elapsed_ms(); }
  double device_compute_ms() const override { return compute_timer_.elapsed_ms(); }
  std::unique_ptr<ListStorage> make_list_storage() const override {
    return std::make_unique<DeviceListStorage>();
  }
  std::unique_ptr<PaddedStorage> make_padded_storage() const override {
    return std::make_unique<DevicePaddedStorage>();
  }

 protected:
  // Sizes the results for `kernel` over n targets, then times launch(outputs) as the compute.
  template <class Launch>
  void timed_compute(Kernel kernel, std::size_t n, Launch&& launch) {
    const KernelOutputs out = results_.prepare(kernel, n);
    compute_timer_.start(stream_);
    launch(out);
    RAYCUT_CUDA_CHECK_LAUNCH();
    compute_timer_.stop(stream_);
    results_.commit();
  }

  // The lists of every GPU method: run(f) must run functor f over every target's pairs.
  // `exact`: the pass's ExactImages (null without images), where per-pair cutoffs decide their
  // band in double as the search does.
  template <class Run>
  void device_neighbours(ListStorage& storage, std::size_t n, const ListOptions& options,
                         const ExactImages* exact, Run&& run) {
    auto& list = static_cast<DeviceListStorage&>(storage);
    std::uint32_t* counts = list.prepare_counts(n, options);
    const ListFilter filter = list_filter(list, options, n, exact);
    count_list(filter, counts, run);
    run(list.prepare_fill(list.scan_counts(stream_), filter));
  }
  // The static-capacity list of every GPU method: the same passes, the scan and the end on the
  // stream, nothing read back (the count, offsets and cutoffs in static_scratch_).
  template <class Run>
  void device_static_neighbours(const StaticPairs& out, const ListOptions& options, std::size_t n,
                                const ExactImages* exact, Run&& run) {
    if (n > 0) {
      DeviceListStorage& list = static_scratch_;
      std::uint32_t* counts = list.prepare_counts(n, options);
      const ListFilter filter = list_filter(list, options, n, exact);
      count_list(filter, counts, run);
      list.scan(stream_);
      ListFill fill{filter,  list.offsets_data(), nullptr, nullptr,
                    nullptr, out.shifts,          out.i,   out.j};
      fill.capacity = out.capacity;
      run(fill);
      finish_static_pairs_on_device(list.offsets_data() + n, out, plan_misfit_, stream_);
    } else {
      finish_static_pairs_on_device(nullptr, out, nullptr, stream_);
    }
  }
  template <class Run>
  void device_padded(PaddedStorage& storage, std::size_t n, std::uint32_t k, bool half, bool shifts,
                     Run&& run) {
    auto& list = static_cast<DevicePaddedStorage&>(storage);
    run(list.prepare(n, k, half, shifts, stream_));
    list.read_report(stream_);
  }

  // What a list keeps: its half orientation and per-pair cutoffs, staged in `list`.
  ListFilter list_filter(DeviceListStorage& list, const ListOptions& options, std::size_t n,
                         const ExactImages* exact) const {
    ListFilter filter{options.half, list.stage_cutoffs(options.cutoffs, n, stream_),
                      options.half && options.any_row};
    if (exact && filter.cutoffs.active()) filter.cutoffs.exact = *exact;
    return filter;
  }

  cudaStream_t stream_ = nullptr;
  // A build that reused its plan (Points::reuse.misfit): what the device found no longer fits,
  // reported as the count of static lists.
  const int* plan_misfit_ = nullptr;
  DeviceResults results_;
  DeviceListStorage static_scratch_;
  EventTimer build_timer_, compute_timer_;
};

// A CUDA method whose pairs are walked by one traversal (Self::run(f) runs functor f through it):
// the built-in kernels, the lists and the caller's functors all go through it.
template <class Self>
class CudaPairMethod : public GpuMethod {
 public:
  void compute(Kernel kernel, const KernelOptions& options) override {
    timed_compute(kernel, self().size(), [&](const KernelOutputs& out) {
      with_kernel(kernel, options, self().pair_pass().cutoff_squared, out,
                  [&](const auto& f) { self().run(f); });
    });
  }
  void neighbours(ListStorage& list, const ListOptions& options) override {
    device_neighbours(list, self().size(), options, self().pair_pass().images.exact,
                      [&](const auto& f) { self().run(f); });
  }
  void padded_neighbours(PaddedStorage& list, std::uint32_t k, bool half, bool shifts) override {
    device_padded(list, self().size(), k, half, shifts, [&](const auto& f) { self().run(f); });
  }
  void static_neighbours(const StaticPairs& out, const ListOptions& options,
                         std::size_t n) override {
    device_static_neighbours(out, options, n, self().pair_pass().images.exact,
                             [&](const auto& f) { self().run(f); });
  }

 private:
  const Self& self() const { return static_cast<const Self&>(*this); }
};

}  // namespace raycut::detail::cuda
