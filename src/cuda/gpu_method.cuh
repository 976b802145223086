// What every GPU method shares beyond build and query: device space, per-target results kept on
// the device, CUDA-event timing of the two phases. A GPU method derives from this, fills
// results_ in compute() and brackets its phases with build_timer_ / compute_timer_.
#pragma once

#include "core/method.hpp"
#include "cuda/device_results.cuh"

namespace raycut::detail::cuda {

class GpuMethod : public Method {
 public:
  MemorySpace space() const override { return MemorySpace::device; }
  Results results() const override { return results_.to_host(); }
  ResultsView results_view() const override { return results_.view(); }
  void synchronize() override { RAYCUT_CUDA_CHECK(cudaDeviceSynchronize()); }
  double device_build_ms() const override { return build_timer_.elapsed_ms(); }
  double device_compute_ms() const override { return compute_timer_.elapsed_ms(); }

 protected:
  DeviceResults results_;
  EventTimer build_timer_, compute_timer_;
};

}  // namespace raycut::detail::cuda
