// Runs a caller's pair functor (include/raycut/functor.hpp says its shape) through the traversal
// of a built CPU method, fused: no list in between. GPU methods: include/raycut/cuda/pairs.cuh.
//
//   struct Coulomb { using Accumulator = float; const float* q; float* energy; ... };  //
//   functor.hpp raycut::Engine engine("cell-list"); engine.build(positions, cutoff);
//   raycut::for_each_pair(engine, Coulomb{q, energy.data()});
//
// Also the one CPU pair loop of the library's own methods (src/cpu/host_method.hpp).
//
// Engine is only declared here (detail/pair_pass.hpp): the traversal reaches a built engine
// through detail::PairPassAccess, defined in the library, so this header and the CPU methods
// including it do not depend on the Engine class. Callers include <raycut/engine.hpp> to build one.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <type_traits>

#include "raycut/detail/host_threads.hpp"
#include "raycut/detail/images.hpp"
#include "raycut/detail/pair_pass.hpp"
#include "raycut/error.hpp"
#include "raycut/kernels.hpp"
#include "raycut/predicate.hpp"

namespace raycut {
namespace detail {

// Calls on_pair(j, r, r2) for every in-range candidate j != i of target i, r = x_j - x_i, by
// the predicate of policy `images` (in_range_of: with images, candidates in the float band are
// decided in double). walk(i, f) calls f(j, xyz_j) for every candidate source j of target i,
// each at most once.
template <class Images, class Walk, class OnPair>
void for_each_in_range(const Images& images, std::size_t i, const float* xyz, float cutoff_squared,
                       const Walk& walk, OnPair&& on_pair) {
  const float xi = xyz[3 * i], yi = xyz[3 * i + 1], zi = xyz[3 * i + 2];
  walk(i, [&](std::size_t j, const float* xj) {
    if (j == i) return;
    Vec3 r{xj[0] - xi, xj[1] - yi, xj[2] - zi};
    float r2 = squared_distance(r.x, r.y, r.z);
    if (in_range_of(images, cutoff_squared, static_cast<std::uint32_t>(i),
                    static_cast<std::uint32_t>(j), r, r2))
      on_pair(j, r, r2);
  });
}

// Runs functor f for every target (points [0, n)), in parallel over targets (OpenMP), visited
// in `order` (null: 0 .. n - 1; each target's own sum is the same in any order); candidate
// points become the caller's sources and shifts through `images` (detail/images.hpp).
template <class Walk, class F, class Images = NoImages>
void run_host(std::size_t n, const float* xyz, float cutoff_squared, const Walk& walk, const F& f,
              const Images& images = {}, const std::uint32_t* order = nullptr) {
  static_assert(check_functor<F>());
  const auto visit = [&](const std::uint32_t i) {
    typename F::Accumulator acc = initial_state(f, i);
    const typename Images::Target ti = images.target(i);
    for_each_in_range(images, i, xyz, cutoff_squared, walk,
                      [&](std::size_t point, Vec3 r, float r2) {
                        const auto k = static_cast<std::uint32_t>(point);
                        std::uint32_t j;
                        Shift s{};
                        if (resolve(f, images, ti, true, i, k, k, j, s))
                          apply(f, acc, i, j, r, r2, s);
                      });
    f.finish(i, acc);
  };
  if (order) {
#pragma omp parallel for schedule(dynamic, 256) if (n >= parallel_targets)
    for (std::size_t t = 0; t < n; ++t) visit(order[t]);
  } else {
#pragma omp parallel for schedule(dynamic, 256) if (n >= parallel_targets)
    for (std::size_t t = 0; t < n; ++t) visit(static_cast<std::uint32_t>(t));
  }
}

// run_host over a HostPass, with its images.
template <class Walk, class F>
void run_host_pass(const PairPass& pass, const Walk& walk, const F& f) {
  with_images<F>(pass, [&](const auto& images) {
    run_host(pass.n, pass.host.xyz, pass.cutoff_squared, walk, f, images, pass.host.order);
  });
}

// A HostPass's function-pointer walk as a walk callable.
struct HostPassWalk {
  const HostPass& pass;
  template <class OnCandidate>
  void operator()(std::size_t i, OnCandidate&& on_candidate) const {
    using C = std::remove_reference_t<OnCandidate>;
    pass.walk(
        pass.method, i,
        [](void* context, std::size_t j, const float* xj) { (*static_cast<C*>(context))(j, xj); },
        &on_candidate);
  }
};

}  // namespace detail

// Runs f for every target of the built engine, on the host. The engine's method must work on the
// host (Engine::space() == host); GPU methods: raycut::cuda::for_each_pair (pairs.cuh, nvcc).
template <class F>
void for_each_pair(const Engine& engine, const F& f) {
  static_assert(detail::check_functor<F>(), "raycut::for_each_pair: see the messages above");
  const detail::PairPass pass = detail::PairPassAccess::of(engine);
  if (pass.kind == detail::PassKind::none) return;  // an engine over no points
  if (pass.kind != detail::PassKind::host)
    throw Error(ErrorCode::unsupported,
                "raycut::for_each_pair: method '" + std::string(pass.method) +
                    "' works on the GPU: use raycut::cuda::for_each_pair from "
                    "<raycut/cuda/pairs.cuh>, compiled by nvcc");
  detail::run_host_pass(pass, detail::HostPassWalk{pass.host}, f);
}

}  // namespace raycut
