// The host side every ray-tracing method shares: optional Morton sort, the margin, the
// acceleration structure, the fused launches and the neighbour list. A method adds only its
// primitives (build input) and its programs.
#pragma once

#include <optix.h>

#include <cstdint>

#include "core/method.hpp"
#include "cuda/device_results.cuh"
#include "cuda/grid_common.cuh"
#include "optix/context.hpp"
#include "optix/launch_params.hpp"

namespace raycut::detail::optix {

class RayTracingMethod : public cuda::GpuMethod {
 public:
  void build(const float* xyz, std::size_t n, float cutoff) override;
  bool update(const float* xyz, std::size_t n, float cutoff) override;
  void set_update_policy(const UpdatePolicy& policy) override { policy_ = policy; }
  void compute(Kernel kernel, const KernelOptions& options) override;
  void neighbours(ListStorage& list, const ListOptions& options) override;
  void padded_neighbours(PaddedStorage& list, std::uint32_t k, bool half) override;

 protected:
  RayTracingMethod(bool sorted, const PipelineSpec& programs);

  // Fills the method's primitive buffers from the (maybe sorted) positions and describes them.
  // The build input's pointers must stay valid until the next call.
  virtual OptixBuildInput primitives(const float* xyz, std::uint32_t n, float cutoff,
                                     float margin) = 0;

 private:
  LaunchParams base_params() const;
  // One launch running functor f (one of the modes the programs know) for every target.
  template <class F>
  void launch(const F& f);
  // Positions into xyz_, in the method's order (the permutation of the last build, if sorted).
  void arrange(const float* xyz);
  // Largest displacement of any particle since the last full build.
  float max_displacement(const float* xyz);

  bool sorted_;
  UpdatePolicy policy_;
  Pipeline pipeline_;
  Accel accel_;
  OptixTraversableHandle handle_ = 0;
  std::uint32_t n_ = 0;
  float cutoff_ = 0, margin_ = 0;
  cuda::DeviceBuffer<float> xyz_;
  cuda::DeviceBuffer<float> built_xyz_;        // caller's order, at the last full build
  cuda::DeviceBuffer<unsigned> displacement_;  // float bits of the largest squared move
  cuda::DeviceBuffer<std::uint64_t> keys_;
  cuda::DeviceBuffer<std::uint32_t> ids_;
  cuda::DeviceBuffer<unsigned char> sort_temp_;
  cuda::BoundingBox bbox_;
};

// Launch configuration for one thread per element.
constexpr unsigned block_size = 256;
inline unsigned blocks_for(std::size_t n) {
  return static_cast<unsigned>((n + block_size - 1) / block_size);
}

}  // namespace raycut::detail::optix
