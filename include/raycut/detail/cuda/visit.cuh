// What every CUDA traversal does with a candidate and with a target's finished state: the one
// place where a functor (include/raycut/kernels.hpp) meets a traversal. nvcc only.
#pragma once

#include <cuda_runtime.h>
#include <math_constants.h>

#include <cstdint>

#include "raycut/detail/cuda/check.cuh"
#include "raycut/detail/images.hpp"
#include "raycut/kernels.hpp"
#include "raycut/predicate.hpp"

namespace raycut::detail::cuda {

// One candidate point k (at `index` of the image table) of target i, `in` by the shared
// predicate: the functor's terms when taken (detail/images.hpp maps k to the caller's source and
// shift). A functor whose terms vanish at r2 = +inf is fed that instead of a branch (a few
// instructions per pair, and some lane of a warp is in range at almost every step: the branch
// would only add its own cost); the others branch.
template <class F, class Images>
__device__ __forceinline__ void visit(const F& f, typename F::Accumulator& acc, bool in,
                                      std::uint32_t i, std::uint32_t k, std::uint32_t index, Vec3 r,
                                      float r2, const Images& images,
                                      const typename Images::Target& ti) {
  std::uint32_t j;
  Shift s{};
  const bool take = resolve(f, images, ti, in, i, k, index, j, s);
  if constexpr (vanishes_at_infinity<F>::value) {
    apply(f, acc, i, j, r, take ? r2 : CUDART_INF_F, s);
  } else {
    if (take) apply(f, acc, i, j, r, r2, s);
  }
}

// The accumulators of G consecutive lanes combined (F::combine), in a fixed butterfly order: the
// result does not change from run to run. Every lane ends with the total.
template <int G, class F>
__device__ __forceinline__ void combine_lanes(typename F::Accumulator& acc) {
  using A = typename F::Accumulator;
  static_assert(sizeof(A) % sizeof(unsigned) == 0,
                "a functor's Accumulator shared by lanes must be made of 32-bit words");
  constexpr int words = sizeof(A) / sizeof(unsigned);
#pragma unroll
  for (int offset = G / 2; offset > 0; offset /= 2) {
    unsigned mine[words], theirs[words];
    memcpy(mine, &acc, sizeof(A));
#pragma unroll
    for (int w = 0; w < words; ++w) theirs[w] = __shfl_xor_sync(0xffffffffu, mine[w], offset);
    A other;
    memcpy(&other, theirs, sizeof(A));
    F::combine(acc, other);
  }
}

inline unsigned blocks_for(std::uint64_t count, int threads) {
  return static_cast<unsigned>((count + threads - 1) / threads);
}

}  // namespace raycut::detail::cuda
