// Custom AABBs (method 4): one zero-length ray per target from its own position; traversal offers
// every source box containing the origin. The intersection program applies THE predicate and
// reports in-range sources; the pair work is in any-hit, which REQUIRE_SINGLE_ANYHIT_CALL makes
// run once per (ray, primitive). OptiX promises no such thing for intersection programs, so the
// paper's "compute inside the intersection program" is not exactly-once by contract.
#include "optix/device_common.cuh"

using namespace raycut::detail::optix;

extern "C" __constant__ LaunchParams params;

extern "C" __global__ void __raygen__aabb() {
  const std::uint32_t i = optixGetLaunchIndex().x;
  TargetState s = begin_target(params, i);
  unsigned p0, p1;
  state_payload(s, p0, p1);
  optixTrace(params.handle, position(params, i), make_float3(1.0f, 0.0f, 0.0f), 0.0f, 1e-16f, 0.0f,
             OptixVisibilityMask(255), OPTIX_RAY_FLAG_DISABLE_CLOSESTHIT, 0, 1, 0, p0, p1);
  finish_target(params, s);
}

extern "C" __global__ void __intersection__aabb() {
  const std::uint32_t j = optixGetPrimitiveIndex();
  const std::uint32_t i = target_state().target;
  if (j == i) return;  // self, excluded by index
  const PairGeometry g = pair_geometry(params, i, j);
  if (!raycut::in_range(g.r2, params.cutoff_squared)) return;
  optixReportIntersection(optixGetRayTmax(), 0);
}

extern "C" __global__ void __anyhit__aabb() {
  TargetState& s = target_state();
  const std::uint32_t j = optixGetPrimitiveIndex();
  accept_pair(params, s, j, pair_geometry(params, s.target, j));
  optixIgnoreIntersection();
}

// The paper's variant, for comparison (method optix-aabb-fused): the pair work inside the
// intersection program, nothing reported, no any-hit. Exactly once only as far as OptiX calls
// the intersection program once per (ray, primitive), which it does in every test we ran but
// does not promise.
extern "C" __global__ void __intersection__aabb_fused() {
  TargetState& s = target_state();
  const std::uint32_t j = optixGetPrimitiveIndex();
  if (j == s.target) return;
  const PairGeometry g = pair_geometry(params, s.target, j);
  if (raycut::in_range(g.r2, params.cutoff_squared)) accept_pair(params, s, j, g);
}
