// Double squares (method 3), one oversized triangle per square: four +x rays per target from its
// box's corners. Any-hit keeps the pair only on the corner given by the signs of (dy, dz) and the
// face given by the sign of dx (src/geometry/ray_geometry.hpp): one (ray, triangle) per pair,
// crossed well inside the triangle; REQUIRE_SINGLE_ANYHIT_CALL makes that one call.
#include "geometry/ray_geometry.hpp"
#include "optix/device_common.cuh"

using namespace raycut::detail;
using namespace raycut::detail::optix;

extern "C" __constant__ LaunchParams params;

extern "C" __global__ void __raygen__triangles() {
  const std::uint32_t i = optixGetLaunchIndex().x;
  TargetState s = begin_target(params, i);
  unsigned p0, p1;
  state_payload(s, p0, p1);
  const float3 x = position(params, i);
  const float length = geometry::corner_ray_length(params.cutoff, params.margin);
  for (unsigned corner = 0; corner < 4; ++corner) {
    float o[3];
    geometry::corner_ray_origin(x.x, x.y, x.z, corner, params.cutoff, params.margin, o);
    unsigned p2 = corner;
    optixTrace(params.handle, make_float3(o[0], o[1], o[2]), make_float3(1.0f, 0.0f, 0.0f), 0.0f,
               length, 0.0f, OptixVisibilityMask(255), OPTIX_RAY_FLAG_DISABLE_CLOSESTHIT, 0, 1, 0,
               p0, p1, p2);
  }
  finish_target(params, s);
}

extern "C" __global__ void __anyhit__triangles() {
  TargetState& s = target_state();
  const std::uint32_t primitive = optixGetPrimitiveIndex();
  const std::uint32_t j = primitive >> 1;
  if (j != s.target) {
    const PairGeometry g = pair_geometry(params, s.target, j);
    if (raycut::in_range(g.r2, params.cutoff_squared) &&
        geometry::kept_corner(g.dy, g.dz) == static_cast<int>(optixGetPayload_2()) &&
        geometry::kept_face(g.dx) == static_cast<int>(primitive & 1))
      accept_pair(params, s, j, g);
  }
  optixIgnoreIntersection();
}
