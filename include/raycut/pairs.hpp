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

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include "raycut/detail/host_threads.hpp"
#include "raycut/detail/images.hpp"
#include "raycut/detail/pair_pass.hpp"
#include "raycut/error.hpp"
#include "raycut/host_memory.hpp"
#include "raycut/kernels.hpp"
#include "raycut/predicate.hpp"

namespace raycut {
namespace detail {

// The index of the lowest set bit of x != 0 (C++17: this header also reaches nvcc).
inline int lowest_set_bit(std::uint64_t x) {
#if defined(__GNUC__)
  return __builtin_ctzll(x);
#else
  int n = 0;
  for (; !(x & 1); x >>= 1) ++n;
  return n;
#endif
}

// Calls on_pair(j, r, r2) for every in-range candidate j != i of target i at target_xyz,
// r = x_j - x_i, by
// the predicate of policy `images` (in_range_of: with images, candidates in the float band are
// decided in double). runs_of(i, out) writes the CandidateRuns that hold every candidate point of
// target i (at most max_candidate_runs) and returns how many. Two steps per block of a run: r2
// of every candidate and whether it is below out_of_range_from, over arrays (vectorised, no
// branch); then the predicate and on_pair for those alone, in the run's order. Most candidates
// are out (5 in 6 in a cell list of cells C wide), and a branch on each mispredicted often
// (lists and lj_forces 1.6-2.4x faster on one CPU thread: docs/pair-pass.md, "The CPU loop").
// Candidates whose source (CandidateRun::source, where a run gives it) is below lowest_source are
// dropped in the first step too: a half list's row i keeps no source below i. Candidates at a
// slot below first_slot (CandidateRun::slot) are not read at all: the half stencil. on_pair also
// gets the candidate's slot.
template <class Images, class RunsOf, class OnPair>
void for_each_in_range(const Images& images, std::size_t i, const float* target_xyz,
                       float cutoff_squared, const RunsOf& runs_of, OnPair&& on_pair,
                       std::uint32_t lowest_source = 0, std::uint32_t first_slot = 0) {
  const float xi = target_xyz[0], yi = target_xyz[1], zi = target_xyz[2];
  const float out_from = out_of_range_from(images, cutoff_squared);
  CandidateRun runs[max_candidate_runs];
  const std::size_t run_count = runs_of(i, runs);
  constexpr std::size_t block = 64, lanes = CandidateRun::padding;
  float r2[block];
  alignas(8) unsigned char near[block];
  for (std::size_t u = 0; u < run_count; ++u) {
    CandidateRun& run = runs[u];
    if (first_slot > run.slot) {  // the run's points from first_slot on (every group readable)
      const std::size_t skip = std::min<std::size_t>(first_slot - run.slot, run.count);
      run.x += skip, run.y += skip, run.z += skip;
      if (run.index) run.index += skip;
      if (run.source) run.source += skip;
      if (run.image) run.image += skip;
      run.first += static_cast<std::uint32_t>(skip);
      run.slot += static_cast<std::uint32_t>(skip);
      run.count -= skip;
    }
    for (std::size_t b = 0; b < run.count; b += block) {
      const std::size_t m = std::min(block, run.count - b);
      const float *x = run.x + b, *y = run.y + b, *z = run.z + b;
      // Whole groups of `lanes` (the run's arrays are readable that far): no scalar tail.
      if (lowest_source != 0 && run.source) {
        const std::uint32_t* source = run.source + b;
        for (std::size_t w = 0; w < m; w += lanes)
          for (std::size_t t = w; t < w + lanes; ++t) {
            r2[t] = squared_distance(x[t] - xi, y[t] - yi, z[t] - zi);
            near[t] = (r2[t] < out_from) & (source[t] >= lowest_source);
          }
      } else {
        for (std::size_t w = 0; w < m; w += lanes)
          for (std::size_t t = w; t < w + lanes; ++t) {
            r2[t] = squared_distance(x[t] - xi, y[t] - yi, z[t] - zi);
            near[t] = r2[t] < out_from;
          }
      }
      for (std::size_t t = m; t % lanes != 0; ++t) near[t] = 0;
      // The flags as one bit per candidate (8 bytes 0 or 1 gathered by one multiplication),
      // then the near candidates: a branch per near one, and one that mispredicts per block.
      std::uint64_t mask = 0;
      for (std::size_t w = 0; w < m; w += 8) {
        std::uint64_t flags;
        std::memcpy(&flags, near + w, 8);
        mask |= ((flags * 0x0102040810204080u) >> 56) << w;
      }
      for (; mask != 0; mask &= mask - 1) {
        const std::size_t t = static_cast<std::size_t>(lowest_set_bit(mask));
        const std::uint32_t j = run.point(b + t);
        if (j == i) continue;
        Vec3 r{x[t] - xi, y[t] - yi, z[t] - zi};
        float d2 = r2[t];
        if (in_range_of(images, cutoff_squared, static_cast<std::uint32_t>(i), j, r, d2))
          on_pair(j, r, d2, run.image ? run.image + b + t : nullptr,
                  run.slot + static_cast<std::uint32_t>(b + t));
      }
    }
  }
}

// The lowest source f keeps in row i: f.lowest_source(i) where f says (a half list), else 0.
template <class F, class = void>
struct has_lowest_source : std::false_type {};
template <class F>
struct has_lowest_source<F, std::void_t<decltype(std::declval<const F&>().lowest_source(0u))>>
    : std::true_type {};
template <class F>
std::uint32_t lowest_source_of(const F& f, std::uint32_t i) {
  if constexpr (has_lowest_source<F>::value)
    return f.lowest_source(i);
  else
    return 0;
}

// Runs functor f for every target (points [0, n)), in parallel over targets (OpenMP), visited
// in `order` (null: 0 .. n - 1; each target's own sum is the same in any order), at positions
// order_xyz (3 per target in that order; null: xyz by index); candidate points become the
// caller's sources and shifts through `images` (detail/images.hpp). `slots` (HostPass::slots)
// and `image_counts` (ImageTables::image_counts, with images) let a half list whose rows may
// follow the traversal (wants_stencil) take each home pair from its lower slot, as the CUDA
// grid does (grid_pass.cuh, StencilRows): a target without images reads only the later slots.
template <class RunsOf, class F, class Images = NoImages>
void run_host(std::size_t n, const float* xyz, float cutoff_squared, const RunsOf& runs_of,
              const F& f, const Images& images = {}, const std::uint32_t* order = nullptr,
              const float* order_xyz = nullptr, const std::uint32_t* slots = nullptr,
              const std::uint32_t* image_counts = nullptr) {
  static_assert(check_functor<F>());
  // Points with images (banded): the stencil needs their counts and the table (active).
  const bool stencil =
      slots && wants_stencil(f) && (!Images::banded || (Images::active && image_counts));
  const auto visit = [&](const std::uint32_t i, const float* target_xyz) {
    typename F::Accumulator acc = initial_state(f, i);
    const typename Images::Target ti = images.target(i);
    const std::uint32_t t = stencil ? slots[i] : 0;
    const bool half_rows = stencil && !(Images::banded && image_counts[i] > 0);
    for_each_in_range(
        images, i, target_xyz, cutoff_squared, runs_of,
        [&](std::size_t point, Vec3 r, float r2, const PointImage* entry, std::uint32_t slot) {
          const auto k = static_cast<std::uint32_t>(point);
          const bool home = stencil && k < n;
          if (home && slot <= t) return;  // met from its lower slot
          const auto& g = for_candidate(f, home);
          std::uint32_t j;
          Shift s{};
          if (resolve(g, images, ti, true, i, k, k, j, s, entry)) apply(g, acc, i, j, r, r2, s);
        },
        stencil ? 0 : lowest_source_of(f, i), half_rows ? t + 1 : 0);
    f.finish(i, acc);
  };
  const auto target_xyz = [&](std::size_t t) {
    return order ? (order_xyz ? order_xyz + 3 * t : xyz + 3 * std::size_t{order[t]}) : xyz + 3 * t;
  };
  // Below parallel_targets no OpenMP region at all (host_threads.hpp says why). Not through its
  // for_each_index: GCC then stopped inlining into a list pass's candidate loop (a 256-atom
  // cell's list 1.18x slower: docs/benchmarks.md, "No OpenMP region in a small call").
  if (n < parallel_targets) {
    for (std::size_t t = 0; t < n; ++t)
      visit(order ? order[t] : static_cast<std::uint32_t>(t), target_xyz(t));
    return;
  }
#pragma omp parallel for schedule(dynamic, 256)
  for (std::size_t t = 0; t < n; ++t)
    visit(order ? order[t] : static_cast<std::uint32_t>(t), target_xyz(t));
}

// run_host for a functor with option::mirror over a traversal in slot order: each pair once, by
// the half stencil (a home pair from its lower slot; a pair with an image point by the half
// list's rule, i < j or i == j and S positive, from a target with images, which reads every
// slot), its term computed once from Accumulator{} and combined into both particles: into the
// target's accumulator, and, mirrored, into a per-thread sum by the other's slot. Then each
// particle's per-thread sums, in thread order, and finish. The targets go to the threads in
// fixed chunks: the same bits on every run with the same number of threads (another number
// changes the order of the sums, and may change the last bits). False, having run nothing, where
// the sums would leave less than as much again of the host memory budget: the caller then
// computes each pair from both sides, which needs no sums.
template <class RunsOf, class F, class Images>
bool run_host_pair_once(std::size_t n, const RunsOf& runs_of, const F& f, const Images& images,
                        const std::uint32_t* order, const float* order_xyz,
                        const std::uint32_t* slots, const std::uint32_t* image_counts,
                        float cutoff_squared) {
  using Accumulator = typename F::Accumulator;
  std::uint32_t slot_count = 0;  // home slots: the sums are kept by slot, in cell order
  for (std::size_t i = 0; i < n; ++i) slot_count = std::max(slot_count, slots[i] + 1);
  int threads = 1;
#if defined(_OPENMP)
  if (n >= parallel_targets) threads = std::max(1, omp_get_max_threads());
#endif
  const double bytes = static_cast<double>(threads) * slot_count * sizeof(Accumulator);
  if (host_memory_checked(bytes) && 2 * bytes > host_memory_budget().bytes) return false;
  std::vector<Accumulator> sums(static_cast<std::size_t>(threads) * slot_count);
  // Thread `thread` of `team`: chunks of 256 targets dealt to the threads in turn (as
  // schedule(static, 256) deals them), so the sums are the same on every run. One thread runs
  // outside any team (host_threads.hpp says why), which an orphaned `omp for` could not: called
  // from a caller's own parallel region it would share the caller's team.
  const auto accumulate = [&](int thread, int team) {
    Accumulator* const mine = sums.data() + static_cast<std::size_t>(thread) * slot_count;
    constexpr std::size_t chunk = 256;
    for (std::size_t first = chunk * thread; first < n; first += chunk * team)
      for (std::size_t v = first; v < std::min(n, first + chunk); ++v) {
        const std::uint32_t i = order[v];
        const std::uint32_t t = slots[i];
        const typename Images::Target ti = images.target(i);
        const bool half_rows = !(Images::banded && image_counts[i] > 0);
        Accumulator acc{};
        for_each_in_range(
            images, i, order_xyz + 3 * v, cutoff_squared, runs_of,
            [&](std::size_t point, Vec3 r, float r2, const PointImage* entry, std::uint32_t slot) {
              const auto k = static_cast<std::uint32_t>(point);
              std::uint32_t j = k;  // a home point is its own particle
              if (k < n) {
                if (slot <= t) return;  // met from its lower slot
              } else {
                Shift s{};
                if (!resolve(f, images, ti, true, i, k, k, j, s, entry)) return;
                if (!half_keeps(i, j, s)) return;  // met from j as well
              }
              Accumulator term{};
              apply(f, term, i, j, r, r2);
              F::combine(acc, term);
              F::mirror(term);
              F::combine(mine[slots[j]], term);
            },
            0, half_rows ? t + 1 : 0);
        F::combine(mine[t], acc);
      }
  };
#if defined(_OPENMP)
  if (threads > 1) {
#pragma omp parallel num_threads(threads)
    accumulate(omp_get_thread_num(), omp_get_num_threads());
  } else {
    accumulate(0, 1);
  }
#else
  accumulate(0, 1);
#endif
  for_each_index(n, parallel_targets, 0, [&](std::size_t i) {
    Accumulator total = sums[slots[i]];
    for (int other = 1; other < threads; ++other)
      F::combine(total, sums[static_cast<std::size_t>(other) * slot_count + slots[i]]);
    f.finish(static_cast<std::uint32_t>(i), total);
  });
  return true;
}

// run_host over a HostPass, with its images.
template <class RunsOf, class F>
void run_host_pass(const PairPass& pass, const RunsOf& runs_of, const F& f) {
  if constexpr (has_mirror<F>::value) {
    const HostPass& host = pass.host;
    const ImageTables& images = pass.images;
    if (host.slots && host.order && host.order_xyz && images.candidates_are_sources) {
      if (!images.active() && pass.points == pass.n &&
          run_host_pair_once(pass.n, runs_of, f, NoImages{}, host.order, host.order_xyz, host.slots,
                             nullptr, pass.cutoff_squared))
        return;
      // The half rule reads an image's j and S: the table, whatever the functor reads.
      if (images.active() && images.exact && images.image_counts &&
          run_host_pair_once(pass.n, runs_of, f, WithImages{images.table(nullptr), *images.exact},
                             host.order, host.order_xyz, host.slots, images.image_counts,
                             pass.cutoff_squared))
        return;
    }
  }
  with_images<F>(pass, [&](const auto& images) {
    run_host(pass.n, pass.host.xyz, pass.cutoff_squared, runs_of, f, images, pass.host.order,
             pass.host.order_xyz, pass.images.candidates_are_sources ? pass.host.slots : nullptr,
             pass.images.image_counts);
  });
}

// A HostPass's function-pointer runs as a callable.
struct HostPassRuns {
  const HostPass& pass;
  std::size_t operator()(std::size_t i, CandidateRun* out) const {
    return pass.runs(pass.method, i, out);
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
  detail::run_host_pass(pass, detail::HostPassRuns{pass.host}, f);
}

}  // namespace raycut
