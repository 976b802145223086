// Launch parameters of the custom-AABB method: plain data shared by the host side
// (aabb_method.cu) and the device programs (programs.cu).
#pragma once

#include <optix_types.h>

#include <cstdint>

#include "cuda/device_results.cuh"

namespace raycut::detail::optix {

enum class AabbMode : int {
  count,  // fused kernels: the Kernel value selects the functor
  lj,
  smooth,
  list_count,  // neighbour list, pass 1: neighbours per target
  list_fill,   // neighbour list, pass 2: write them at their offsets
};

struct AabbParams {
  OptixTraversableHandle handle;
  const float* xyz;             // positions, in the method's (maybe sorted) order
  const std::uint32_t* origin;  // slot -> caller's particle index; null when unsorted
  std::uint32_t n;
  float cutoff_squared;
  AabbMode mode;
  float lj_four_epsilon, lj_sigma_squared;
  cuda::OutputView out;               // indexed by the caller's particle index
  std::uint32_t* list_counts;         // list_count: per caller index
  const std::uint64_t* list_offsets;  // list_fill: per caller index
  std::uint32_t* list_indices;
};

}  // namespace raycut::detail::optix
