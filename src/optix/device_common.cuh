// Device-side pieces every ray-tracing method's programs share: the per-target state reached
// through the payload, the pair accumulation by mode, and the per-target store. Included by the
// programs.cu files only (OptiX IR).
#pragma once

#include <optix.h>

#include <new>
#include <type_traits>

#include "optix/launch_params.hpp"
#include "raycut/kernels.hpp"
#include "raycut/predicate.hpp"

namespace raycut::detail::optix {

// The per-target state of whichever functor the launch runs: its Accumulator, in place.
struct TargetState {
  alignas(8) unsigned char storage[64];
  std::uint32_t target;
};

template <class F>
__device__ __forceinline__ typename F::Accumulator& state_of(TargetState& s, const F&) {
  static_assert(sizeof(typename F::Accumulator) <= sizeof(TargetState::storage),
                "TargetState::storage too small for this functor's Accumulator");
  return *reinterpret_cast<typename F::Accumulator*>(s.storage);
}

__device__ __forceinline__ std::uint32_t caller_index(const LaunchParams& p, std::uint32_t slot) {
  return p.origin ? p.origin[slot] : slot;
}

__device__ __forceinline__ TargetState begin_target(const LaunchParams& p, std::uint32_t i) {
  TargetState s;
  s.target = i;
  with_functor(p, [&](const auto& f) {
    using A = typename std::decay_t<decltype(f)>::Accumulator;
    new (s.storage) A(initial_state(f, caller_index(p, i)));
  });
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
  // The local frame's difference times 1 / scale: the caller's d, exactly (ray_method.cu).
  PairGeometry g;
  g.dx = (p.xyz[3 * j] - p.xyz[3 * i]) * p.inverse_scale;
  g.dy = (p.xyz[3 * j + 1] - p.xyz[3 * i + 1]) * p.inverse_scale;
  g.dz = (p.xyz[3 * j + 2] - p.xyz[3 * i + 2]) * p.inverse_scale;
  g.r2 = squared_distance(g.dx, g.dy, g.dz);
  return g;
}

// One kept (target, source j) pair: the launch's functor.
__device__ __forceinline__ void accept_pair(const LaunchParams& p, TargetState& s, std::uint32_t j,
                                            const PairGeometry& g) {
  const std::uint32_t ci = caller_index(p, s.target), cj = caller_index(p, j);
  with_functor(p, [&](const auto& f) {
    if (accepts(f, ci, cj)) apply(f, state_of(s, f), ci, cj, Vec3{g.dx, g.dy, g.dz}, g.r2);
  });
}

__device__ __forceinline__ void finish_target(const LaunchParams& p, TargetState& s) {
  const std::uint32_t ci = caller_index(p, s.target);
  with_functor(p, [&](const auto& f) { f.finish(ci, state_of(s, f)); });
}

__device__ __forceinline__ float3 position(const LaunchParams& p, std::uint32_t i) {
  return make_float3(p.xyz[3 * i], p.xyz[3 * i + 1], p.xyz[3 * i + 2]);
}

}  // namespace raycut::detail::optix
