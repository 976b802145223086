// Launch parameters every ray-tracing method shares (plain data, host and device). A method's
// own parameter block starts with a LaunchParams and adds its geometry numbers.
#pragma once

#include <optix_types.h>

#include <cstdint>
#include <type_traits>
#include <utility>

#include "core/list_functors.hpp"
#include "raycut/kernels.hpp"

namespace raycut::detail::optix {

// The functors a launch can run (the programs are compiled ahead, so the functor is chosen by a
// mode among the library's own): every built-in kernel's (the catalogue, BuiltinKernels), then
// the list passes.
template <class... Fs>
struct FunctorList {};
template <class... Specs>
FunctorList<decltype(Specs::make(std::declval<const KernelOptions&>(), 0.0f,
                                 std::declval<const KernelOutputs&>()))...,
            ListCount, FilteredListCount, ListFill, PaddedFill>
    ray_functors_of(KernelList<Specs...>);
using RayFunctors = decltype(ray_functors_of(BuiltinKernels{}));

// A launch's mode: the position of its functor in RayFunctors.
using RayMode = int;

template <class F, class... Fs>
constexpr RayMode mode_in(FunctorList<Fs...>) {
  RayMode mode = 0, found = -1;
  ((std::is_same_v<F, Fs> ? found = mode : ++mode), ...);
  return found;
}
template <class F>
inline constexpr RayMode mode_of = mode_in<F>(RayFunctors{});

// One slot per functor, side by side (their default member initializers rule out a union).
template <class F>
struct FunctorSlot {
  F functor;
};
template <class... Fs>
struct FunctorSlots : FunctorSlot<Fs>... {};
template <class... Fs>
FunctorSlots<Fs...> slots_of(FunctorList<Fs...>);
using RayFunctorSlots = decltype(slots_of(RayFunctors{}));

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
  RayFunctorSlots functors;
};

// The launch's mode and functor, for any functor the programs know.
template <class F>
inline void set_functor(LaunchParams& p, const F& f) {
  static_assert(mode_of<F> >= 0, "a functor the ray-tracing programs were not compiled for");
  p.mode = mode_of<F>;
  static_cast<FunctorSlot<F>&>(p.functors).functor = f;
}

// Calls visit(functor) with the functor of the launch's mode: a chain of compile-time modes.
template <class Visit, class... Fs, std::size_t... Modes>
__host__ __device__ __forceinline__ void visit_functor(const LaunchParams& p, Visit& visit,
                                                       FunctorList<Fs...>,
                                                       std::index_sequence<Modes...>) {
  (void)((p.mode == static_cast<RayMode>(Modes)
              ? (visit(static_cast<const FunctorSlot<Fs>&>(p.functors).functor), true)
              : false) ||
         ...);
}
template <class Visit, class... Fs>
__host__ __device__ __forceinline__ void visit_functor(const LaunchParams& p, Visit& visit,
                                                       FunctorList<Fs...> list) {
  visit_functor(p, visit, list, std::index_sequence_for<Fs...>{});
}
template <class Visit>
__host__ __device__ __forceinline__ void with_functor(const LaunchParams& p, Visit&& visit) {
  visit_functor(p, visit, RayFunctors{});
}

}  // namespace raycut::detail::optix
