// Device programs of the custom-AABB method (compiled to OptiX IR, embedded in the library).
//
// Each target casts one zero-length ray from its own position; traversal offers every source box
// (half-width C, inflated against rounding) that contains the origin. The intersection program
// applies THE shared predicate and reports in-range sources only; the work is done in any-hit,
// which the geometry flag REQUIRE_SINGLE_ANYHIT_CALL guarantees runs once per (ray, primitive):
// OptiX does not promise that for intersection programs, so the paper's "compute inside the
// intersection program" is not exactly-once by contract. Any-hit ignores every hit, so the
// traversal never stops and never shortens the ray.
#include <optix.h>

#include "optix/aabb/params.hpp"
#include "raycut/kernels.hpp"
#include "raycut/predicate.hpp"

using namespace raycut;
using namespace raycut::detail::optix;

extern "C" __constant__ AabbParams params;

namespace {

struct RayState {
  Accumulator acc;
  std::uint64_t slot;  // list_fill: next index to write
  std::uint32_t target;
};

__device__ RayState* ray_state() {
  const std::uint64_t p =
      (static_cast<std::uint64_t>(optixGetPayload_0()) << 32) | optixGetPayload_1();
  return reinterpret_cast<RayState*>(p);
}

__device__ std::uint32_t caller_index(std::uint32_t slot) {
  return params.origin ? params.origin[slot] : slot;
}

}  // namespace

extern "C" __global__ void __raygen__aabb() {
  const std::uint32_t i = optixGetLaunchIndex().x;
  RayState state;
  state.target = i;
  const std::uint32_t caller = caller_index(i);
  state.slot = params.mode == AabbMode::list_fill ? params.list_offsets[caller] : 0;
  const std::uint64_t p = reinterpret_cast<std::uint64_t>(&state);
  unsigned p0 = static_cast<unsigned>(p >> 32), p1 = static_cast<unsigned>(p);
  const float3 origin =
      make_float3(params.xyz[3 * i], params.xyz[3 * i + 1], params.xyz[3 * i + 2]);
  optixTrace(params.handle, origin, make_float3(1.0f, 0.0f, 0.0f), 0.0f, 1e-16f, 0.0f,
             OptixVisibilityMask(255), OPTIX_RAY_FLAG_DISABLE_CLOSESTHIT, 0, 1, 0, p0, p1);

  switch (params.mode) {
    case AabbMode::count:
      params.out.store<CountKernel>(caller, state.acc);
      break;
    case AabbMode::lj:
      params.out.store<LennardJonesKernel>(caller, state.acc);
      break;
    case AabbMode::smooth:
      params.out.store<SmoothKernel>(caller, state.acc);
      break;
    case AabbMode::list_count:
      params.list_counts[caller] = state.acc.count;
      break;
    case AabbMode::list_fill:
      break;
  }
}

extern "C" __global__ void __intersection__aabb() {
  const std::uint32_t j = optixGetPrimitiveIndex();
  const std::uint32_t i = ray_state()->target;
  if (j == i) return;  // self, excluded by index
  const float dx = params.xyz[3 * j] - params.xyz[3 * i];
  const float dy = params.xyz[3 * j + 1] - params.xyz[3 * i + 1];
  const float dz = params.xyz[3 * j + 2] - params.xyz[3 * i + 2];
  const float r2 = squared_distance(dx, dy, dz);
  if (!in_range(r2, params.cutoff_squared)) return;
  optixReportIntersection(optixGetRayTmax(), 0, __float_as_uint(dx), __float_as_uint(dy),
                          __float_as_uint(dz), __float_as_uint(r2));
}

extern "C" __global__ void __anyhit__aabb() {
  RayState& s = *ray_state();
  const float dx = __uint_as_float(optixGetAttribute_0());
  const float dy = __uint_as_float(optixGetAttribute_1());
  const float dz = __uint_as_float(optixGetAttribute_2());
  const float r2 = __uint_as_float(optixGetAttribute_3());
  switch (params.mode) {
    case AabbMode::count:
    case AabbMode::list_count:
      CountKernel{}(s.acc, dx, dy, dz, r2);
      break;
    case AabbMode::lj:
      LennardJonesKernel{params.lj_four_epsilon, params.lj_sigma_squared}(s.acc, dx, dy, dz, r2);
      break;
    case AabbMode::smooth:
      SmoothKernel{params.cutoff_squared}(s.acc, dx, dy, dz, r2);
      break;
    case AabbMode::list_fill:
      params.list_indices[s.slot++] = caller_index(optixGetPrimitiveIndex());
      break;
  }
  optixIgnoreIntersection();
}
