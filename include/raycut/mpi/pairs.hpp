// A caller's pair functor (include/raycut/kernels.hpp says its shape) over the owned targets of a
// DistributedEngine, fused in its local engines' traversals as raycut::for_each_pair runs one on
// a single engine (host methods; include/raycut/mpi/pairs.cuh runs one on the GPU methods of a
// device-resident engine).
//
//   const std::vector<float> q_local = engine.halo_fields(q_owned.data(), 1);  // owned + halos
//   raycut::mpi::for_each_pair(engine, Coulomb{q_local.data(), energy.data()});
//
// What the functor sees: i is an owned row (0 .. owned() - 1, ids() order; finish(i) is called
// once per owned row, after every pair of it); j is a local source index, owned (< owned()) then
// halos (owned() + k for halo_ids()[k]), the order of halo_fields(), so per-source data comes
// from there; r and r2 as on one engine; S (takes_shift) the pair's global image shift, relative
// to the positions() of each particle's owner (DistributedList::shifts's). Global indices: ids()
// and halo_ids().
#pragma once

#include <cstdint>
#include <type_traits>
#include <vector>

#include "raycut/kernels.hpp"
#include "raycut/mpi/distributed.hpp"
#include "raycut/pairs.hpp"

namespace raycut::mpi {
namespace detail {

// The caller's functor over one of the local engines: local targets to owned rows, the engine's
// sources to local source indices, shifts to global ones. A target whose pairs come from both
// engines (owned rows only: a boundary particle) keeps its state between the two passes in
// `carry`: the halo pass stores it there instead of finishing, the owned pass starts from it.
// Runs on either side: on the host it refers to f (Held = const F&), on a GPU traversal it holds
// a copy (Held = F: copied to the device by value; all rows only there, every pointer a device
// one).
template <class F, class Held = const F&>
struct LocalPass {
  using Accumulator = typename F::Accumulator;
  static constexpr bool takes_shift = true;
  enum class Kind { all_rows, owned, halos };

  Held f;
  Kind kind;
  std::uint32_t owned;              // owned particles: local sources below, rows of all_rows
  const std::int32_t* halo_shifts;  // 3 per halo
  const std::uint32_t* boundary;    // halo pass: query b is owned row boundary[b]
  const std::int32_t* slot;         // owned pass: owned row -> its carry slot, or -1
  Accumulator* carry;               // one per boundary row

  RAYCUT_HD std::uint32_t row(std::uint32_t i) const {
    return kind == Kind::halos ? boundary[i] : i;
  }
  RAYCUT_HD std::uint32_t source(std::uint32_t j) const {
    return kind == Kind::halos ? owned + j : j;
  }
  RAYCUT_HD Shift global(std::uint32_t j, const Shift& s) const {
    if (j < owned) return s;
    const std::int32_t* h = halo_shifts + 3 * (j - owned);
    return {s.a + h[0], s.b + h[1], s.c + h[2]};
  }

  RAYCUT_HD Accumulator init(std::uint32_t i) const {
    if (kind == Kind::owned && slot[i] >= 0) return carry[slot[i]];
    if (kind == Kind::all_rows && i >= owned) return Accumulator{};  // a halo's row: unused
    return initial_state(f, row(i));
  }
  RAYCUT_HD bool accepts(std::uint32_t i, std::uint32_t j, const Shift& s) const {
    if (kind == Kind::all_rows && i >= owned) return false;  // a halo's row
    const std::uint32_t k = source(j);
    return raycut::accepts(f, row(i), k, global(k, s));
  }
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t i, std::uint32_t j, Vec3 r, float r2,
                            const Shift& s) const {
    const std::uint32_t k = source(j);
    apply(f, acc, row(i), k, r, r2, global(k, s));
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const {
    if (kind == Kind::halos)
      carry[i] = acc;
    else if (kind == Kind::owned || i < owned)
      f.finish(i, acc);
  }
};

// Whether f's operator() reads only the pair (r, r2): no source index, no shift, no filter (the
// built-in kernels but sph_force declare uses_source = false).
template <class F>
inline constexpr bool reads_pair_only =
    !raycut::uses_source<F>::value && !raycut::has_accepts<F>::value &&
    !raycut::takes_shift<F>::value;

// LocalPass for such a functor, on the host: nothing to map per pair but the row, and no
// accepts() or shift, so each traversal runs its plain loop (no image lookup per pair: an open
// cloud's). All rows only for a functor whose operator() reads no row data either (`halo_rows`:
// halo rows are computed, as on one engine, and not finished).
template <class F>
struct RowPass {
  using Accumulator = typename F::Accumulator;
  static constexpr bool uses_source = false;
  using Kind = typename LocalPass<F>::Kind;

  const F& f;
  Kind kind;
  std::uint32_t owned;
  const std::uint32_t* boundary;  // halo pass: query b is owned row boundary[b]
  const std::int32_t* slot;       // owned pass: owned row -> its carry slot, or -1
  Accumulator* carry;             // one per boundary row

  std::uint32_t row(std::uint32_t i) const { return kind == Kind::halos ? boundary[i] : i; }
  Accumulator init(std::uint32_t i) const {
    if (kind == Kind::owned && slot[i] >= 0) return carry[slot[i]];
    if (kind == Kind::all_rows && i >= owned) return Accumulator{};  // a halo's row: unused
    return initial_state(f, row(i));
  }
  void operator()(Accumulator& acc, std::uint32_t i, std::uint32_t j, Vec3 r, float r2) const {
    f(acc, row(i), j, r, r2);
  }
  void finish(std::uint32_t i, Accumulator& acc) const {
    if (kind == Kind::halos)
      carry[i] = acc;
    else if (kind == Kind::owned || i < owned)
      f.finish(i, acc);
  }
};

// The one visitor of the local engines (host methods): f over every owned row, through the
// engine over owned + halos (all rows), or with owned rows only the boundary rows' pairs with
// halos first (`halos`: the query engine, null when it has nothing to do), then every owned row's
// pairs among owned particles, which finishes each row once. The distributed engine runs its
// kernels, lists and sph_force through it; for_each_pair below a caller's functor.
// `rows_unread`: f's operator() reads no data of its row i (the built-in kernels), so that all
// rows may run it on halo rows too.
template <class F>
void for_each_local_pair(const Engine& local, const Engine* halos,
                         const std::vector<std::uint32_t>& boundary, bool owned_rows_only,
                         std::uint32_t owned, const std::int32_t* halo_shifts, const F& f,
                         bool rows_unread = false) {
  using Pass = LocalPass<F>;
  using Kind = typename Pass::Kind;
  const auto pass = [&](Kind kind, const std::uint32_t* rows, const std::int32_t* slots,
                        typename F::Accumulator* carry, const auto& run) {
    if constexpr (reads_pair_only<F>)
      if (kind != Kind::all_rows || rows_unread)
        return run(RowPass<F>{f, kind, owned, rows, slots, carry});
    run(Pass{f, kind, owned, halo_shifts, rows, slots, carry});
  };
  const auto on = [](const Engine& engine) {
    return [&engine](const auto& p) { raycut::for_each_pair(engine, p); };
  };
  if (!owned_rows_only) {
    pass(Kind::all_rows, nullptr, nullptr, nullptr, on(local));
    return;
  }
  std::vector<typename F::Accumulator> carry;
  std::vector<std::int32_t> slot(owned, -1);
  if (halos) {
    carry.resize(boundary.size());
    pass(Kind::halos, boundary.data(), nullptr, carry.data(), on(*halos));
    for (std::size_t b = 0; b < boundary.size(); ++b) slot[boundary[b]] = static_cast<int>(b);
  }
  pass(Kind::owned, nullptr, slot.data(), carry.data(), on(local));
}

}  // namespace detail

// Runs f for every owned target of the built engine (not collective: halos are the last
// exchange's or refresh's). The method must work on the host (a GPU method: raycut::mpi::cuda::
// for_each_pair, include/raycut/mpi/pairs.cuh); Error(unsupported) otherwise.
template <class F>
void for_each_pair(const DistributedEngine& engine, const F& f) {
  if (engine.local_engine().space() != MemorySpace::host)
    throw Error(ErrorCode::unsupported,
                "raycut::mpi::for_each_pair: method '" + engine.local_engine().method() +
                    "' works on the GPU; this runs host methods (cell-list, brute-force), "
                    "raycut::mpi::cuda::for_each_pair (raycut/mpi/pairs.cuh) GPU ones");
  detail::for_each_local_pair(engine.local_engine(), engine.halo_engine(), engine.boundary(),
                              engine.owned_rows_only(), static_cast<std::uint32_t>(engine.owned()),
                              engine.halo_shifts().data(), f);
}

}  // namespace raycut::mpi
