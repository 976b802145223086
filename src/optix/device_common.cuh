// Device-side pieces every ray-tracing method's programs share: the per-target state reached
// through the payload, the pair accumulation by mode, and the per-target store. Included by the
// programs.cu files only (OptiX IR).
#pragma once

#include <optix.h>

#include "optix/launch_params.hpp"
#include "raycut/kernels.hpp"
#include "raycut/predicate.hpp"

namespace raycut::detail::optix {

struct TargetState {
  Accumulator acc;
  std::uint64_t slot;  // list_fill: next index to write
  std::uint32_t target;
};

__device__ __forceinline__ std::uint32_t caller_index(const LaunchParams& p, std::uint32_t slot) {
  return p.origin ? p.origin[slot] : slot;
}

__device__ __forceinline__ TargetState begin_target(const LaunchParams& p, std::uint32_t i) {
  TargetState s;
  s.target = i;
  s.slot = p.mode == RayMode::list_fill ? p.list_offsets[caller_index(p, i)] : 0;
  return s;
}

// Payload registers 0 and 1 carry the address of the target's state (on the raygen's stack).
__device__ __forceinline__ void state_payload(TargetState& s, unsigned& p0, unsigned& p1) {
  const auto a = reinterpret_cast<std::uint64_t>(&s);
  p0 = static_cast<unsigned>(a >> 32);
  p1 = static_cast<unsigned>(a);
}

__device__ __forceinline__ TargetState& target_state() {
  const std::uint64_t a =
      (static_cast<std::uint64_t>(optixGetPayload_0()) << 32) | optixGetPayload_1();
  return *reinterpret_cast<TargetState*>(a);
}

// d = x_source - x_target and its squared norm, by THE shared predicate's arithmetic.
struct PairGeometry {
  float dx, dy, dz, r2;
};

__device__ __forceinline__ PairGeometry pair_geometry(const LaunchParams& p, std::uint32_t i,
                                                      std::uint32_t j) {
  PairGeometry g;
  g.dx = p.xyz[3 * j] - p.xyz[3 * i];
  g.dy = p.xyz[3 * j + 1] - p.xyz[3 * i + 1];
  g.dz = p.xyz[3 * j + 2] - p.xyz[3 * i + 2];
  g.r2 = squared_distance(g.dx, g.dy, g.dz);
  return g;
}

// One kept (target, source j) pair: accumulate by mode.
__device__ __forceinline__ void accept_pair(const LaunchParams& p, TargetState& s, std::uint32_t j,
                                            const PairGeometry& g) {
  const std::uint32_t ci = caller_index(p, s.target), cj = caller_index(p, j);
  switch (p.mode) {
    case RayMode::count:
    case RayMode::list_count:
      CountKernel{}(s.acc, ci, cj, g.dx, g.dy, g.dz, g.r2);
      break;
    case RayMode::lj:
      p.lj(s.acc, ci, cj, g.dx, g.dy, g.dz, g.r2);
      break;
    case RayMode::smooth:
      p.smooth(s.acc, ci, cj, g.dx, g.dy, g.dz, g.r2);
      break;
    case RayMode::sph_density:
      p.sph_density(s.acc, ci, cj, g.dx, g.dy, g.dz, g.r2);
      break;
    case RayMode::sph_force:
      p.sph_force(s.acc, ci, cj, g.dx, g.dy, g.dz, g.r2);
      break;
    case RayMode::list_fill:
      p.list_indices[s.slot++] = cj;
      break;
  }
}

__device__ __forceinline__ void finish_target(const LaunchParams& p, const TargetState& s) {
  const std::uint32_t caller = caller_index(p, s.target);
  switch (p.mode) {
    case RayMode::count:
      p.out.store(caller, s.acc, CountKernel{});
      break;
    case RayMode::lj:
      p.out.store(caller, s.acc, p.lj);
      break;
    case RayMode::smooth:
      p.out.store(caller, s.acc, p.smooth);
      break;
    case RayMode::sph_density:
      p.out.store(caller, s.acc, p.sph_density);
      break;
    case RayMode::sph_force:
      p.out.store(caller, s.acc, p.sph_force);
      break;
    case RayMode::list_count:
      p.list_counts[caller] = s.acc.count;
      break;
    case RayMode::list_fill:
      break;
  }
}

__device__ __forceinline__ float3 position(const LaunchParams& p, std::uint32_t i) {
  return make_float3(p.xyz[3 * i], p.xyz[3 * i + 1], p.xyz[3 * i + 2]);
}

}  // namespace raycut::detail::optix
