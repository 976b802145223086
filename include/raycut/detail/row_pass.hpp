// Passes whose rows are not simply an engine's targets: the distributed engine's local engines
// (include/raycut/mpi/distributed.hpp), where a rank computes the rows of its owned particles
// either with one engine over owned + halos (all rows; the halos' rows are not finished) or, owned
// rows only, with two: the owned particles' engine and one with the boundary rows as queries over
// the halos. A row whose pairs come from both keeps its state between the two passes (carried),
// so every row is one sum, finished once: no results are merged afterwards. RowMap says which
// pass runs; a functor wrapper applies it (raycut::mpi's LocalPass for a caller's functor,
// RowPass for the library's own functors, kernels and lists, inside the CPU methods' own loops);
// run_local_rows is the schedule. Not a stable interface.
#pragma once

#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "raycut/engine.hpp"
#include "raycut/kernels.hpp"

namespace raycut::detail {

enum class RowKind {
  all_rows,  // one engine over owned + halos: targets past `owned` are halos', not finished
  owned,     // the owned particles' engine: a boundary row starts from its carried state
  halos,     // boundary rows as queries over the halos: query b is owned row boundary[b], its
             // sources halos (local source owned + j), its state carried, not finished
};

struct RowMap {
  RowKind kind = RowKind::all_rows;
  std::uint32_t owned = 0;
  const std::uint32_t* boundary = nullptr;  // halos: the owned row of each query
  const std::int32_t* slot = nullptr;       // owned: owned row -> its carried state, or -1
  void* carry = nullptr;                    // one functor Accumulator per boundary row
  // 3 per halo: the halo's image shift, added to a pair's local one to make it global (null:
  // no functor of the pass reads shifts).
  const std::int32_t* halo_shifts = nullptr;

  RAYCUT_HD std::uint32_t row(std::uint32_t i) const {
    return kind == RowKind::halos ? boundary[i] : i;
  }
  RAYCUT_HD std::uint32_t source(std::uint32_t j) const {
    return kind == RowKind::halos ? owned + j : j;
  }
  RAYCUT_HD bool halo_row(std::uint32_t i) const { return kind == RowKind::all_rows && i >= owned; }
  // The global shift of a pair with local source k (source()) and local shift s.
  RAYCUT_HD Shift global(std::uint32_t k, const Shift& s) const {
    if (k < owned) return s;
    const std::int32_t* h = halo_shifts + 3 * (k - owned);
    return {s.a + h[0], s.b + h[1], s.c + h[2]};
  }
  template <class F>
  RAYCUT_HD typename F::Accumulator init(const F& f, std::uint32_t i) const {
    using A = typename F::Accumulator;
    if (kind == RowKind::owned && slot[i] >= 0) return static_cast<A*>(carry)[slot[i]];
    if (halo_row(i)) return A{};  // unused
    return initial_state(f, row(i));
  }
  template <class F>
  RAYCUT_HD void finish(const F& f, std::uint32_t i, typename F::Accumulator& acc) const {
    if (kind == RowKind::halos)
      static_cast<typename F::Accumulator*>(carry)[i] = acc;
    else if (!halo_row(i))
      f.finish(i, acc);
  }
};

// One of the library's functors (a built-in kernel, a list's count or fill) over mapped rows, in
// a CPU method's own loop (Method::compute_rows, Method::list_rows): rows and sources mapped,
// shifts made global. It declares the same pair call as F, so a functor that reads neither j nor
// S keeps the traversal's plain loop (no image lookup), and filters only when F does; a filter
// also drops the halos' rows of a pass of all rows (a functor writing entries at its rows'
// offsets filters). Without a filter those rows run (the kernels' arrays span owned + halos) and
// are not finished.
template <class F>
struct RowPassBase {
  using Accumulator = typename F::Accumulator;
  using options =
      std::conditional_t<has_accepts<F>::value, functor_options<option::init, option::accepts>,
                         functor_options<option::init>>;
  const F& f;
  RowMap rows;

  Accumulator init(std::uint32_t i) const { return rows.init(f, i); }
  // accepts(i, j) or accepts(i, j, s), as F's pair call (a template: one name, either form).
  template <class... S>
  bool accepts(std::uint32_t i, std::uint32_t j, const S&... s) const {
    if (rows.halo_row(i)) return false;
    const std::uint32_t k = rows.source(j);
    if constexpr (sizeof...(S) == 0)
      return raycut::accepts(f, rows.row(i), k);
    else
      return raycut::accepts(f, rows.row(i), k, rows.global(k, s...));
  }
  void finish(std::uint32_t i, Accumulator& acc) const { rows.finish(f, i, acc); }
};

// The pair call, in F's form (specialisations: plain C++17, the header reaches nvcc).
template <class F, bool reads_source = uses_source<F>::value,
          bool reads_shift = takes_shift<F>::value>
struct RowPass : RowPassBase<F> {
  void operator()(typename F::Accumulator& acc, std::uint32_t i, Vec3 r, float r2) const {
    this->f(acc, this->rows.row(i), r, r2);
  }
};
template <class F>
struct RowPass<F, true, false> : RowPassBase<F> {
  void operator()(typename F::Accumulator& acc, std::uint32_t i, std::uint32_t j, Vec3 r,
                  float r2) const {
    this->f(acc, this->rows.row(i), this->rows.source(j), r, r2);
  }
};
template <class F>
struct RowPass<F, true, true> : RowPassBase<F> {
  void operator()(typename F::Accumulator& acc, std::uint32_t i, std::uint32_t j, Vec3 r, float r2,
                  const Shift& s) const {
    const std::uint32_t k = this->rows.source(j);
    this->f(acc, this->rows.row(i), k, r, r2, this->rows.global(k, s));
  }
};

// The schedule for `owned` rows with accumulators of type A: one pass of all rows over `local`,
// or, owned rows only, the query engine's pass (`halos`, null when it has nothing to do; query b
// is owned row boundary[b]) and then the owned engine's, which finishes every row once.
// halo_shifts: RowMap's (null when the functor reads no shifts).
// pass(engine, rows) runs one.
template <class A, class Pass>
void run_local_rows(const Engine& local, const Engine* halos,
                    const std::vector<std::uint32_t>& boundary, bool owned_rows_only,
                    std::uint32_t owned, const std::int32_t* halo_shifts, Pass&& pass) {
  if (!owned_rows_only) {
    pass(local, RowMap{RowKind::all_rows, owned, nullptr, nullptr, nullptr, halo_shifts});
    return;
  }
  std::vector<A> carry;
  std::vector<std::int32_t> slot(owned, -1);
  if (halos) {
    carry.resize(boundary.size());
    pass(*halos,
         RowMap{RowKind::halos, owned, boundary.data(), nullptr, carry.data(), halo_shifts});
    for (std::size_t b = 0; b < boundary.size(); ++b) slot[boundary[b]] = static_cast<int>(b);
  }
  pass(local, RowMap{RowKind::owned, owned, nullptr, slot.data(), carry.data(), halo_shifts});
}

}  // namespace raycut::detail
