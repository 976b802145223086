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
// from there; r and r2 as on one engine; S (to an operator() that takes a Shift) the pair's
// global image shift, relative to the positions() of each particle's owner
// (DistributedList::shifts's). Global indices: ids() and halo_ids().
#pragma once

#include <cstdint>
#include <type_traits>
#include <vector>

#include "raycut/detail/row_pass.hpp"
#include "raycut/kernels.hpp"
#include "raycut/mpi/distributed.hpp"
#include "raycut/pairs.hpp"

namespace raycut::mpi {
namespace detail {

// The caller's functor over one of the local engines (raycut/detail/row_pass.hpp): local
// targets to owned rows, the engine's sources to local source indices, shifts to global ones; a
// boundary row's state carried between the two passes of owned rows only. Runs on either side: on
// the host it refers to f (Held = const F&), on a GPU traversal it holds a copy (Held = F: copied
// to the device by value; all rows only there, every pointer a device one).
template <class F, class Held = const F&>
struct LocalPass {
  using Accumulator = typename F::Accumulator;
  using options = functor_options<option::init, option::accepts>;

  Held f;
  raycut::detail::RowMap rows;  // with the halos' shifts

  RAYCUT_HD Accumulator init(std::uint32_t i) const { return rows.init(f, i); }
  RAYCUT_HD bool accepts(std::uint32_t i, std::uint32_t j, const Shift& s) const {
    if (rows.halo_row(i)) return false;  // a halo's row: not the caller's
    const std::uint32_t k = rows.source(j);
    return raycut::accepts(f, rows.row(i), k, rows.global(k, s));
  }
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t i, std::uint32_t j, Vec3 r, float r2,
                            const Shift& s) const {
    const std::uint32_t k = rows.source(j);
    apply(f, acc, rows.row(i), k, r, r2, rows.global(k, s));
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const { rows.finish(f, i, acc); }
};

// A caller's functor over every owned row of the local engines (host methods), the schedule of
// raycut/detail/row_pass.hpp: one engine of all rows, or with owned rows only the query engine
// (`halos`, null when it has nothing to do) and then the owned engine.
template <class F>
void for_each_local_pair(const Engine& local, const Engine* halos,
                         const std::vector<std::uint32_t>& boundary, bool owned_rows_only,
                         std::uint32_t owned, const std::int32_t* halo_shifts, const F& f) {
  raycut::detail::run_local_rows<typename F::Accumulator>(
      local, halos, boundary, owned_rows_only, owned, halo_shifts,
      [&](const Engine& engine, const raycut::detail::RowMap& rows) {
        raycut::for_each_pair(engine, LocalPass<F>{f, rows});
      });
}

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
  detail::for_each_local_pair(engine.local_engine(), engine.halo_engine(), engine.boundary(),
                              engine.owned_rows_only(), static_cast<std::uint32_t>(engine.owned()),
                              engine.halo_shifts().data(), f);
}

}  // namespace raycut::mpi
