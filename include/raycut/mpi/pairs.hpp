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
  using options = functor_options<option::init, option::accepts>;
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

}  // namespace detail

// Runs f for every owned target of the built engine (not collective: halos are the last
// exchange's or refresh's). The method must work on the host (a GPU method: raycut::mpi::cuda::
// for_each_pair, include/raycut/mpi/pairs.cuh); Error(unsupported) otherwise.
template <class F>
void for_each_pair(const DistributedEngine& engine, const F& f) {
  static_assert(raycut::detail::check_functor<F>(),
                "raycut::mpi::for_each_pair: see the messages above");
  if (engine.local_engine().space() != MemorySpace::host)
    throw Error(ErrorCode::unsupported,
                "raycut::mpi::for_each_pair: method '" + engine.local_engine().method() +
                    "' works on the GPU; this runs host methods (cell-list, brute-force), "
                    "raycut::mpi::cuda::for_each_pair (raycut/mpi/pairs.cuh) GPU ones");
  using Pass = detail::LocalPass<F>;
  using Kind = typename Pass::Kind;
  const auto owned = static_cast<std::uint32_t>(engine.owned());
  const std::int32_t* halo_shifts = engine.halo_shifts().data();
  if (!engine.owned_rows_only()) {
    raycut::for_each_pair(engine.local_engine(),
                          Pass{f, Kind::all_rows, owned, halo_shifts, nullptr, nullptr, nullptr});
    return;
  }
  // Owned rows only: the boundary rows' pairs with halos first, then every owned row's pairs
  // among owned particles, which finishes each row once.
  const std::vector<std::uint32_t>& boundary = engine.boundary();
  std::vector<typename F::Accumulator> carry;
  std::vector<std::int32_t> slot(owned, -1);
  if (const Engine* halos = engine.halo_engine()) {
    carry.resize(boundary.size());
    raycut::for_each_pair(
        *halos, Pass{f, Kind::halos, owned, halo_shifts, boundary.data(), nullptr, carry.data()});
    for (std::size_t b = 0; b < boundary.size(); ++b) slot[boundary[b]] = static_cast<int>(b);
  }
  raycut::for_each_pair(engine.local_engine(), Pass{f, Kind::owned, owned, halo_shifts, nullptr,
                                                    slot.data(), carry.data()});
}

}  // namespace raycut::mpi
