// Runs a caller's pair functor (include/raycut/functor.hpp says its shape) through the traversal
// of a built engine, fused in the method's own kernel, on any CPU or CUDA method. Compile with
// nvcc; the functor's operator() and finish() must be __host__ __device__ (RAYCUT_HD) and it
// is copied to the device by value (device pointers inside for GPU methods, host pointers for
// CPU methods: Engine::space() says which).
//
//   struct Coulomb {
//     using Accumulator = float;
//     const float* charge; float* energy;  // device pointers
//     RAYCUT_HD void operator()(float& e, std::uint32_t i, std::uint32_t j, raycut::Vec3,
//                               float r2) const { e += charge[i] * charge[j] * rsqrtf(r2); }
//     RAYCUT_HD void finish(std::uint32_t i, float& e) const { energy[i] = e; }
//   };
//   raycut::cuda::for_each_pair(engine, Coulomb{q, e});   // queued on the engine's stream
//
// The OptiX methods run their programs compiled ahead and refuse: Error(unsupported).
#pragma once

#include <cuda_runtime.h>

#include <string>

#include "raycut/detail/cuda/brute_force_pass.cuh"
#include "raycut/detail/cuda/grid_paper_pass.cuh"
#include "raycut/detail/cuda/grid_pass.cuh"
#include "raycut/engine.hpp"
#include "raycut/pairs.hpp"

namespace raycut::cuda {

// Runs f over every target of the built engine. GPU methods queue the kernel on `stream` (the
// engine's own when null) and return without waiting; CPU methods run it on the host.
template <class F>
void for_each_pair(const Engine& engine, const F& f, cudaStream_t stream = nullptr) {
  static_assert(raycut::detail::check_functor<F>(),
                "raycut::cuda::for_each_pair: see the messages above");
  const detail::PairPass pass = raycut::detail::PairPassAccess::of(engine);
  if (!stream) stream = static_cast<cudaStream_t>(engine.stream());
  switch (pass.kind) {
    case detail::PassKind::none:  // an engine over no points
      return;
    case detail::PassKind::host:
      raycut::for_each_pair(engine, f);
      return;
    case detail::PassKind::brute_force_gpu:
      detail::cuda::run_brute_force(pass, f, stream);
      return;
    case detail::PassKind::grid_paper:
      detail::cuda::run_grid_paper(pass, f, stream);
      return;
    case detail::PassKind::grid:
      detail::cuda::run_grid(pass, f, stream);
      return;
  }
}

}  // namespace raycut::cuda
