// Per-target outputs of GPU methods: allocation by kernel, the device-side store, the copy back,
// the CUDA-event timer, the CSR assembly and the GpuMethod base. Shared by every CUDA and OptiX
// method.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>
#include <vector>

#include "core/method.hpp"
#include "cuda/check.cuh"
#include "cuda/device_buffer.cuh"
#include "raycut/engine.hpp"
#include "raycut/kernels.hpp"

namespace raycut::detail::cuda {

// Raw pointers a kernel writes; null for what the kernel does not produce.
struct OutputView {
  std::uint32_t* count = nullptr;
  float* energy = nullptr;
  float* force = nullptr;  // 3 per target

  // The target's sums, after the kernel's finish().
  template <class K>
  __device__ __forceinline__ void store(std::size_t i, Accumulator acc, const K& kernel) const {
    kernel.finish(acc);
    if constexpr (K::has_count) count[i] = acc.count;
    if constexpr (K::has_energy) energy[i] = acc.energy;
    if constexpr (K::has_force) {
      force[3 * i] = acc.fx;
      force[3 * i + 1] = acc.fy;
      force[3 * i + 2] = acc.fz;
    }
  }
};

class DeviceResults {
 public:
  // Sizes the buffers for `kernel` over n targets (nothing is cleared: every target is stored).
  OutputView prepare(Kernel kernel, std::size_t n);
  Results to_host() const;
  ResultsView view() const;

 private:
  Kernel kernel_ = Kernel::count;
  std::size_t n_ = 0;
  DeviceBuffer<std::uint32_t> count_;
  DeviceBuffer<float> energy_, force_;
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

// What every GPU method shares: positions and results on the device, the results kept until the
// next compute, the CUDA-event timers of build and compute, and the synchronisation.
class GpuMethod : public Method {
 public:
  MemorySpace space() const override { return MemorySpace::device; }
  Results results() const override { return results_.to_host(); }
  ResultsView results_view() const override { return results_.view(); }
  void synchronize() override { RAYCUT_CUDA_CHECK(cudaDeviceSynchronize()); }
  double device_build_ms() const override { return build_timer_.elapsed_ms(); }
  double device_compute_ms() const override { return compute_timer_.elapsed_ms(); }

 protected:
  // Sizes the results for `kernel` over n targets, then times launch(out) as the compute.
  template <class Launch>
  void timed_compute(Kernel kernel, std::size_t n, Launch&& launch) {
    const OutputView out = results_.prepare(kernel, n);
    compute_timer_.start();
    launch(out);
    RAYCUT_CUDA_CHECK_LAUNCH();
    compute_timer_.stop();
  }

  DeviceResults results_;
  EventTimer build_timer_, compute_timer_;
};

// Assembles a CSR list: count(counts) must write each target's number of neighbours into
// counts[0..n); fill(offsets, indices) must write target i's neighbours into
// indices[offsets[i] ..). Both launch kernels on the default stream.
template <class Count, class Fill>
NeighbourList build_neighbour_list(std::size_t n, Count count, Fill fill);

// Exclusive prefix sum of counts[0..n) into offsets[0..n] (offsets[n] = total), on the device.
void exclusive_scan(const std::uint32_t* counts, std::uint64_t* offsets, std::size_t n);

template <class Count, class Fill>
NeighbourList build_neighbour_list(std::size_t n, Count count, Fill fill) {
  DeviceBuffer<std::uint32_t> counts(n);
  DeviceBuffer<std::uint64_t> offsets(n + 1);
  count(counts.data());
  exclusive_scan(counts.data(), offsets.data(), n);
  NeighbourList list;
  list.offsets.resize(n + 1);
  RAYCUT_CUDA_CHECK(cudaMemcpy(list.offsets.data(), offsets.data(), (n + 1) * sizeof(std::uint64_t),
                               cudaMemcpyDeviceToHost));
  const std::uint64_t total = list.offsets[n];
  require_device_memory(total * sizeof(std::uint32_t), "the neighbour list");
  DeviceBuffer<std::uint32_t> indices(total > 0 ? total : 1);
  fill(static_cast<const std::uint64_t*>(offsets.data()), indices.data());
  allocate_indices(list, total);
  RAYCUT_CUDA_CHECK(cudaMemcpy(list.indices.data(), indices.data(), total * sizeof(std::uint32_t),
                               cudaMemcpyDeviceToHost));
  return list;
}

}  // namespace raycut::detail::cuda
