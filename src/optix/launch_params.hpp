// Launch parameters every ray-tracing method shares (plain data, host and device). A method's
// own parameter block starts with a LaunchParams and adds its geometry numbers.
#pragma once

#include <optix_types.h>

#include <cstdint>

#include "cuda/device_results.cuh"

namespace raycut::detail::optix {

enum class RayMode : int {
  count,  // fused kernels
  lj,
  smooth,
  list_count,  // neighbour list, pass 1: neighbours per target
  list_fill,   // neighbour list, pass 2: write them at their offsets
};

struct LaunchParams {
  OptixTraversableHandle handle;
  const float* xyz;             // positions in the method's (maybe sorted) order
  const std::uint32_t* origin;  // slot -> caller's particle index; null when unsorted
  std::uint32_t n;
  float cutoff, cutoff_squared;
  float margin;  // e of src/geometry/ray_geometry.hpp
  RayMode mode;
  float lj_four_epsilon, lj_sigma_squared;
  cuda::OutputView out;               // indexed by the caller's particle index
  std::uint32_t* list_counts;         // list_count: per caller index
  const std::uint64_t* list_offsets;  // list_fill: per caller index
  std::uint32_t* list_indices;
};

}  // namespace raycut::detail::optix
