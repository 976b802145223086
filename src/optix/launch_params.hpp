// Launch parameters every ray-tracing method shares (plain data, host and device). A method's
// own parameter block starts with a LaunchParams and adds its geometry numbers.
#pragma once

#include <optix_types.h>

#include <cstdint>

#include "cuda/device_results.cuh"
#include "raycut/kernels.hpp"

namespace raycut::detail::optix {

enum class RayMode : int {
  count,  // fused kernels
  lj,
  smooth,
  sph_density,
  sph_force,
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
  // The functor of the fused mode (the others unused).
  LennardJonesKernel lj;
  SmoothKernel smooth;
  SphDensityKernel sph_density;
  SphForceKernel sph_force;
  cuda::OutputView out;               // indexed by the caller's particle index
  std::uint32_t* list_counts;         // list_count: per caller index
  const std::uint64_t* list_offsets;  // list_fill: per caller index
  std::uint32_t* list_indices;
};

}  // namespace raycut::detail::optix
