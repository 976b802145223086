// Built-in spheres (method 2): three axis rays per target, started far enough back that no
// in-range sphere contains their origin (src/geometry/ray_geometry.hpp says why). Any-hit keeps
// the pair only on the axis of largest |d_k| (ties to the lowest axis); built-in spheres report
// the entry only and REQUIRE_SINGLE_ANYHIT_CALL makes that one call, so each pair counts once.
#include "geometry/ray_geometry.hpp"
#include "optix/device_common.cuh"

using namespace raycut::detail;
using namespace raycut::detail::optix;

extern "C" __constant__ LaunchParams params;

extern "C" __global__ void __raygen__spheres() {
  const std::uint32_t i = optixGetLaunchIndex().x;
  TargetState s = begin_target(params, i);
  unsigned p0, p1;
  state_payload(s, p0, p1);
  const geometry::SphereRays rays = geometry::sphere_rays(params.cutoff, params.margin);
  const float3 x = position(params, i);
  for (unsigned axis = 0; axis < 3; ++axis) {
    const float3 dir = make_float3(axis == 0, axis == 1, axis == 2);
    const float3 origin =
        make_float3(x.x - rays.back * dir.x, x.y - rays.back * dir.y, x.z - rays.back * dir.z);
    unsigned p2 = axis;
    optixTrace(params.handle, origin, dir, 0.0f, rays.length, 0.0f, OptixVisibilityMask(255),
               OPTIX_RAY_FLAG_DISABLE_CLOSESTHIT, 0, 1, 0, p0, p1, p2);
  }
  finish_target(params, s);
}

extern "C" __global__ void __anyhit__spheres() {
  TargetState& s = target_state();
  const std::uint32_t j = optixGetPrimitiveIndex();
  if (j != s.target) {
    const PairGeometry g = pair_geometry(params, s.target, j);
    if (raycut::in_range(g.r2, params.cutoff_squared) &&
        geometry::sphere_axis(g.dx, g.dy, g.dz) == static_cast<int>(optixGetPayload_2()))
      accept_pair(params, s, j, g);
  }
  optixIgnoreIntersection();
}
