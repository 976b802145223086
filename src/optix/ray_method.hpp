// The host side every ray-tracing method shares: optional Morton sort, the margin, the
// acceleration structure, the fused launches and the neighbour list. A method adds only its
// primitives (build input) and its programs.
#pragma once

#include <optix.h>

#include <cstdint>

#include "core/method.hpp"
#include "cuda/device_results.cuh"
#include "cuda/grid_common.cuh"
#include "geometry/ray_geometry.hpp"
#include "optix/context.hpp"
#include "optix/launch_params.hpp"

namespace raycut::detail::optix {

class RayTracingMethod : public cuda::GpuMethod {
 public:
  void build(const float* xyz, std::size_t n, float cutoff) override;
  std::string points_unsupported() const override {
    return "the OptiX programs trace one open set of particles (docs/methods.md: use grid)";
  }
  bool update(const float* xyz, std::size_t n, float cutoff) override;
  void set_update_policy(const UpdatePolicy& policy) override { policy_ = policy; }
  void compute(Kernel kernel, const KernelOptions& options) override;
  void neighbours(ListStorage& list, const ListOptions& options) override;
  void padded_neighbours(PaddedStorage& list, std::uint32_t k, bool half, bool shifts) override;
  void static_neighbours(const StaticPairs& out, const ListOptions& options,
                         std::size_t n) override;

 protected:
  RayTracingMethod(bool sorted, const PipelineSpec& programs);

  // Fills the method's primitive buffers from the (maybe sorted) positions and describes them.
  // The build input's pointers must stay valid until the next call. The positions are in the
  // local frame (x - the exact shift of build()), as the programs see them in LaunchParams::xyz.
  virtual OptixBuildInput primitives(const float* xyz, std::uint32_t n, float cutoff,
                                     float margin) = 0;
  // The method's name and geometry, for the valid-domain check of build().
  virtual const char* name() const = 0;
  virtual geometry::Shape shape() const = 0;

 private:
  LaunchParams base_params() const;
  // One launch running functor f (one of the modes the programs know) for every target.
  template <class F>
  void launch(const F& f);
  // Positions into xyz_, in the method's order (the permutation of the last build, if sorted).
  void arrange(const float* xyz);
  // Largest displacement of any particle since the last full build.
  float max_displacement(const float* xyz);
  // Throws Error(unsupported) when the local magnitude S (in cutoffs) is beyond the geometry's
  // bound (geometry::max_scene_cutoffs), naming the method, S / C and the bound.
  void check_domain(double magnitude, float cutoff) const;
  // Whether x - shift_ is still exact for new positions (else update() rebuilds).
  bool shift_stays_exact(const float* xyz);

  bool sorted_;
  UpdatePolicy policy_;
  Pipeline pipeline_;
  Accel accel_;
  OptixTraversableHandle handle_ = 0;
  std::uint32_t n_ = 0;
  float cutoff_ = 0, margin_ = 0;
  // Local origin per axis: xyz_ holds x - shift_, exact in float (geometry::exact_shift), so the
  // pair vectors, hence the shared predicate and every kernel, are the caller's bit for bit.
  float shift_[3] = {0, 0, 0};
  float scale_ = 1;  // a power of two: the local frame's cutoff is in [1, 2)
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
