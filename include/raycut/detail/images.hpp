// How every traversal (host and device) turns a candidate point into the pair a functor sees:
// the caller's source index j and the image shift S (spec/NEIGHBOURS.md, 2). The one place where
// periodic images, batches and query points meet the functors. A traversal is instantiated with
// NoImages (the points are the caller's particles: j = k, S = 0, nothing to look up) or
// WithImages (tables of src/core/images.hpp), so plain runs pay nothing for images.
#pragma once

#include <cstdint>

#include "raycut/detail/pair_pass.hpp"
#include "raycut/kernels.hpp"

namespace raycut::detail {

struct NoImages {
  static constexpr bool active = false;
};

struct WithImages {
  static constexpr bool active = true;
  const std::uint32_t* source;
  const std::int32_t* shift;
  // S = T_k - T_i of target i (a point index too: targets come first) and candidate point k.
  RAYCUT_HD Shift pair_shift(std::uint32_t i, std::uint32_t k) const {
    const std::int32_t* ti = shift + 3 * std::uint64_t{i};
    const std::int32_t* tk = shift + 3 * std::uint64_t{k};
    return {tk[0] - ti[0], tk[1] - ti[1], tk[2] - ti[2]};
  }
};

// Candidate point k of target i, `in` by the shared predicate: whether functor f takes it, with
// j (the caller's source; a valid index 0 when not taken, for calls fed r2 = +inf) and s set.
// A query point is never a source; the shift is looked up only for functors that take it.
template <class F, class Images>
RAYCUT_HD bool resolve(const F& f, const Images& images, bool in, std::uint32_t i, std::uint32_t k,
                       std::uint32_t& j, Shift& s) {
  if constexpr (Images::active) {
    j = 0;
    if (!in) return false;
    const std::uint32_t source = images.source[k];
    if (source == not_a_source) return false;
    j = source;
    if constexpr (takes_shift<F>::value) s = images.pair_shift(i, k);
  } else {
    j = k;
  }
  return in && accepts(f, i, j, s);
}

// Runs launch(images) with the image policy of `pass`: one instantiation per policy.
template <class Launch>
void with_images(const PairPass& pass, Launch&& launch) {
  if (pass.images.active())
    launch(WithImages{pass.images.source, pass.images.shift});
  else
    launch(NoImages{});
}

}  // namespace raycut::detail
