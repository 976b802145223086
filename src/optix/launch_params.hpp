// Launch parameters every ray-tracing method shares (plain data, host and device). A method's
// own parameter block starts with a LaunchParams and adds its geometry numbers.
#pragma once

#include <optix_types.h>

#include <cstdint>

#include "core/list_functors.hpp"
#include "raycut/kernels.hpp"

namespace raycut::detail::optix {

// Which functor a launch runs (the programs are compiled ahead, so the functor is chosen by a
// mode among the library's own: kernels, list passes).
enum class RayMode : int {
  count,
  lj,
  lj_forces,
  smooth,
  sph_density,
  sph_force,
  list_count,       // neighbour list, pass 1: neighbours per target
  half_list_count,  // the same for a half list
  list_fill,        // neighbour list, pass 2: write them at their offsets
  padded,           // the padded [N, K] matrix
};

struct LaunchParams {
  OptixTraversableHandle handle;
  const float* xyz;             // positions in the local frame, the method's (maybe sorted) order
  const std::uint32_t* origin;  // slot -> caller's particle index; null when unsorted
  std::uint32_t n;
  float cutoff;          // in the local frame (the geometry's)
  float cutoff_squared;  // the caller's C^2 (the predicate's, on the caller's pair vectors)
  float margin;          // e of src/geometry/ray_geometry.hpp, in the local frame
  float inverse_scale;   // local frame -> the caller's units (a power of two: exact)
  RayMode mode;
  // The functor of the mode (the others unused); each writes its outputs by caller index.
  CountKernel count;
  LennardJonesKernel lj;
  LennardJonesForceKernel lj_forces;
  SmoothKernel smooth;
  SphDensityKernel sph_density;
  SphForceKernel sph_force;
  ListCount list_count;
  HalfListCount half_list_count;
  ListFill list_fill;
  PaddedFill padded;
};

// The launch's mode and functor; one overload per functor the programs know.
inline void set_functor(LaunchParams& p, const CountKernel& f) {
  p.mode = RayMode::count;
  p.count = f;
}
inline void set_functor(LaunchParams& p, const LennardJonesKernel& f) {
  p.mode = RayMode::lj;
  p.lj = f;
}
inline void set_functor(LaunchParams& p, const LennardJonesForceKernel& f) {
  p.mode = RayMode::lj_forces;
  p.lj_forces = f;
}
inline void set_functor(LaunchParams& p, const SmoothKernel& f) {
  p.mode = RayMode::smooth;
  p.smooth = f;
}
inline void set_functor(LaunchParams& p, const SphDensityKernel& f) {
  p.mode = RayMode::sph_density;
  p.sph_density = f;
}
inline void set_functor(LaunchParams& p, const SphForceKernel& f) {
  p.mode = RayMode::sph_force;
  p.sph_force = f;
}
inline void set_functor(LaunchParams& p, const ListCount& f) {
  p.mode = RayMode::list_count;
  p.list_count = f;
}
inline void set_functor(LaunchParams& p, const HalfListCount& f) {
  p.mode = RayMode::half_list_count;
  p.half_list_count = f;
}
inline void set_functor(LaunchParams& p, const ListFill& f) {
  p.mode = RayMode::list_fill;
  p.list_fill = f;
}
inline void set_functor(LaunchParams& p, const PaddedFill& f) {
  p.mode = RayMode::padded;
  p.padded = f;
}

// Calls visit(functor) with the functor of the launch's mode.
template <class Visit>
__host__ __device__ __forceinline__ void with_functor(const LaunchParams& p, Visit&& visit) {
  switch (p.mode) {
    case RayMode::count:
      visit(p.count);
      break;
    case RayMode::lj:
      visit(p.lj);
      break;
    case RayMode::lj_forces:
      visit(p.lj_forces);
      break;
    case RayMode::smooth:
      visit(p.smooth);
      break;
    case RayMode::sph_density:
      visit(p.sph_density);
      break;
    case RayMode::sph_force:
      visit(p.sph_force);
      break;
    case RayMode::list_count:
      visit(p.list_count);
      break;
    case RayMode::half_list_count:
      visit(p.half_list_count);
      break;
    case RayMode::list_fill:
      visit(p.list_fill);
      break;
    case RayMode::padded:
      visit(p.padded);
      break;
  }
}

}  // namespace raycut::detail::optix
