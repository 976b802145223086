// The class Engine: build and update, the neighbour lists (CSR, COO pairs, padded), the kernel
// calls (kernels_bindings.cpp), timings and the C++ loop that benchmarks measure against.
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/string_view.h>
#include <nanobind/stl/vector.h>

#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <vector>

#include "arrays.hpp"
#include "bindings.hpp"
#include "errors.hpp"
#include "idle_lists.hpp"
#include "raycut/kernels.hpp"

namespace raycut_py {

namespace {

// Per-pair cutoffs as Python gives them: radii (N,) float64, or species (N,) uint32 with a
// flattened kinds x kinds float64 table (all None: one cutoff).
struct PyPairCutoffs {
  std::optional<HostDoubles> radii;
  std::optional<HostSpecies> species;
  std::optional<HostDoubles> table;

  // The library's view for an engine of n particles; sizes checked here, values by the engine.
  std::optional<raycut::PairCutoffs> view(std::size_t n) const {
    if (!radii && !species && !table) return std::nullopt;
    raycut::PairCutoffs c;
    if (radii) {
      if (radii->shape(0) != n)
        value_error("per-pair cutoffs: " + std::to_string(radii->shape(0)) + " radii for " +
                    std::to_string(n) + " particles (one per particle)");
      c.radii = radii->data();
    }
    if (species || table) {
      if (!species || !table)
        value_error("per-pair cutoffs: a species table needs both species and table");
      if (species->shape(0) != n)
        value_error("per-pair cutoffs: " + std::to_string(species->shape(0)) + " species for " +
                    std::to_string(n) + " particles (one per particle)");
      const auto kinds =
          static_cast<std::uint32_t>(std::llround(std::sqrt(static_cast<double>(table->shape(0)))));
      if (std::size_t{kinds} * kinds != table->shape(0))
        value_error("per-pair cutoffs: the table holds " + std::to_string(table->shape(0)) +
                    " values, not kinds x kinds");
      c.species = species->data();
      c.table = table->data();
      c.kinds = kinds;
    }
    return c;
  }
};

// The list of `engine`'s positions where the method works (a buffer of its own: earlier results
// stay valid).
std::shared_ptr<raycut::NeighbourListBuffer> fill_list(PyEngine& e, bool half, bool distances,
                                                       bool vectors, bool shifts, bool coo = false,
                                                       const PyPairCutoffs& given = {},
                                                       bool any_row = false) {
  std::shared_ptr<raycut::NeighbourListBuffer> list = idle_lists().take();
  Exclusive hold(e.mutex);
  const std::optional<raycut::PairCutoffs> cutoffs = given.view(e.engine.size());
  e.engine.neighbours(*list, raycut::ListOptions{half, distances, vectors, shifts, coo,
                                                 cutoffs ? &*cutoffs : nullptr, any_row});
  return list;
}

// A list's arrays where they are (the list buffer's memory, or a host copy of it with
// `to_host`), with what keeps them alive; the CSR and COO calls below wrap them alike.
struct ListArrays {
  std::shared_ptr<const void> owner;
  MemorySpace space;
  std::size_t targets;
  std::uint64_t pairs;
  const std::uint64_t* offsets;
  const std::uint32_t* indices;
  const std::int64_t *rows, *columns;
  const float *distances, *vectors;
  const std::int32_t* shifts;
  // None unless asked, else the array (shape given) owned by `owner`.
  template <class T>
  nb::object optional(bool asked, const T* data, std::vector<std::size_t> shape) const {
    if (!asked) return nb::none();
    return wrap(data, std::move(shape), dtype_of<T>(), owner, space);
  }
};

ListArrays arrays_of(std::shared_ptr<raycut::NeighbourListBuffer> list, bool to_host) {
  if (to_host && list->space() == MemorySpace::device) {
    auto host = std::make_shared<raycut::NeighbourList>(list->to_host());
    const auto data = [](const auto& v) { return v.empty() ? nullptr : v.data(); };
    return {host,
            MemorySpace::host,
            host->offsets.size() - 1,
            host->offsets.back(),
            host->offsets.data(),
            data(host->indices),
            data(host->rows),
            data(host->columns),
            data(host->distances),
            data(host->vectors),
            data(host->shifts)};
  }
  const auto* l = list.get();
  return {list,      l->space(),   l->size(),      l->pairs(),   l->offsets(), l->indices(),
          l->rows(), l->columns(), l->distances(), l->vectors(), l->shifts()};
}

// CSR: (offsets int64 [N+1], indices int32 [P], distances [P] or None, vectors [P, 3] or None,
// shifts int32 [P, 3] or None).
nb::tuple neighbours(PyEngine& engine, bool half, bool distances, bool vectors, bool to_host,
                     bool shifts, bool any_row) {
  const ListArrays a =
      arrays_of(fill_list(engine, half, distances, vectors, shifts, false, {}, any_row), to_host);
  const std::size_t n = a.targets, pairs = a.pairs;
  return nb::make_tuple(wrap(a.offsets, {n + 1}, dtype_of<std::int64_t>(), a.owner, a.space),
                        wrap(a.indices, {pairs}, index_dtype(n), a.owner, a.space),
                        a.optional(distances, a.distances, {pairs}),
                        a.optional(vectors, a.vectors, {pairs, 3}),
                        a.optional(shifts, a.shifts, {pairs, 3}));
}

// COO pairs (i int64 [P], j int64 [P], d [P] or None, D [P, 3] or None, S int32 [P, 3] or
// None): ASE's "ijdDS", written as COO by the list pass itself (ListOptions::coo).
nb::tuple pairs(PyEngine& engine, bool half, bool distances, bool vectors, bool to_host,
                bool shifts, const std::optional<HostDoubles>& radii,
                const std::optional<HostSpecies>& species,
                const std::optional<HostDoubles>& table) {
  const ListArrays a = arrays_of(
      fill_list(engine, half, distances, vectors, shifts, /*coo=*/true, {radii, species, table}),
      to_host);
  const std::size_t count = a.pairs;
  return nb::make_tuple(a.optional(true, a.rows, {count}), a.optional(true, a.columns, {count}),
                        a.optional(distances, a.distances, {count}),
                        a.optional(vectors, a.vectors, {count, 3}),
                        a.optional(shifts, a.shifts, {count, 3}));
}

// Padded [N, K] (int32; N marks an empty slot), counts [N] (int32), report, and with `shifts`
// S [N, K, 3] (int32; 0 in empty slots).
nb::tuple padded(PyEngine& engine, std::uint64_t wide_k, bool raise_on_overflow, bool to_host,
                 bool shifts, bool half, bool nearest) {
  if (wide_k < 1 || wide_k > std::numeric_limits<std::uint32_t>::max())
    value_error(
        "padded neighbour list: K must be a whole number in [1, 2^32 - 1 = 4294967295], "
        "got " +
        std::to_string(wide_k));
  const auto k = static_cast<std::uint32_t>(wide_k);
  auto list = std::make_shared<raycut::PaddedNeighbourBuffer>();
  raycut::PaddedReport report;
  {
    Exclusive hold(engine.mutex);
    report = engine.engine.padded_neighbours(*list, {.k = k,
                                                     .half = half,
                                                     .shifts = shifts,
                                                     .throw_on_overflow = raise_on_overflow,
                                                     .nearest = nearest});
  }
  const std::size_t n = list->size();
  nb::dict info;
  info["overflowed_rows"] = report.overflowed_rows;
  info["largest_count"] = report.largest_count;
  info["overflowed"] = report.overflowed();
  info["k"] = k;
  if (to_host && list->space() == MemorySpace::device)
    return nb::make_tuple(host_array(list->indices_to_host(), {n, k}, index_dtype(n + 1)),
                          host_array(list->counts_to_host(), {n}, index_dtype(n + 1)), info,
                          shifts ? host_array(list->shifts_to_host(), {n, k, 3}) : nb::none());
  const MemorySpace space = list->space();
  return nb::make_tuple(
      wrap(list->indices(), {n, k}, index_dtype(n + 1), list, space),
      wrap(list->counts(), {n}, index_dtype(n + 1), list, space), info,
      shifts ? wrap(list->shifts(), {n, k, 3}, dtype_of<std::int32_t>(), list, space) : nb::none());
}

}  // namespace

void bind_engine(nb::module_& m) {
  m.def(
      "release_idle_lists", [] { idle_lists().clear(); },
      "Frees the host list buffers kept for reuse (pyraycut.clear_engine_cache calls it).");
  nb::class_<PyEngine>(m, "Engine")
      .def(nb::init<std::string_view>(), nb::arg("method") = "auto")
      .def_prop_ro("method", [](PyEngine& e) { return e.engine.method(); })            // fixed
      .def_prop_ro("space", [](PyEngine& e) { return space_name(e.engine.space()); })  // fixed
      .def_prop_ro("size", [](PyEngine& e) { return locked(e, [](auto& x) { return x.size(); }); })
      .def_prop_ro("sources",
                   [](PyEngine& e) { return locked(e, [](auto& x) { return x.sources(); }); })
      .def_prop_ro("cutoff",
                   [](PyEngine& e) { return locked(e, [](auto& x) { return x.cutoff(); }); })
      .def(
          "set_stream",
          [](PyEngine& e, std::uintptr_t stream) {
            Exclusive hold(e.mutex);
            e.engine.set_stream(reinterpret_cast<void*>(stream));
          },
          nb::arg("stream"))
      .def(
          "set_timed",
          [](PyEngine& e, bool timed) {
            Exclusive hold(e.mutex);
            e.engine.set_timed(timed);
          },
          nb::arg("timed"))
      .def(
          "build",
          [](PyEngine& e, nb::handle positions, double cutoff,
             const std::optional<HostCells>& cells, const std::optional<HostFlags>& pbc,
             const std::optional<HostOffsets>& offsets, nb::handle queries,
             const std::optional<HostOffsets>& query_offsets,
             const std::optional<HostPositions64>& positions64) {
            const float checked = raycut::checked_cutoff(cutoff);  // as given, then float
            const FloatInput in = float_input(positions, "positions");
            const raycut::PositionsView view = positions_view(in);
            FloatInput query_input;
            const raycut::Systems systems =
                make_systems(cells, pbc, offsets, queries, query_offsets, query_input);
            Exclusive hold(e.mutex);
            if (positions64)
              e.engine.build(float64_positions(*positions64, view.size), checked, systems);
            else if (systems.plain())
              e.engine.build(view, checked);
            else
              e.engine.build(view, checked, systems);
          },
          nb::arg("positions"), nb::arg("cutoff"), nb::arg("cells").none() = nb::none(),
          nb::arg("pbc").none() = nb::none(), nb::arg("offsets").none() = nb::none(),
          nb::arg("queries").none() = nb::none(), nb::arg("query_offsets").none() = nb::none(),
          nb::arg("positions64").none() = nb::none())
      .def(
          "update",
          [](PyEngine& e, nb::handle positions, const std::optional<HostPositions64>& positions64) {
            const FloatInput in = float_input(positions, "positions");
            const raycut::PositionsView view = positions_view(in);
            Exclusive hold(e.mutex);
            if (positions64)
              e.engine.update(float64_positions(*positions64, view.size));
            else
              e.engine.update(view);
          },
          nb::arg("positions"), nb::arg("positions64").none() = nb::none())
      .def(
          "set_skin",
          [](PyEngine& e, float skin) {
            Exclusive hold(e.mutex);
            e.engine.set_update_policy(raycut::UpdatePolicy{skin});
          },
          nb::arg("skin"))
      .def("compute", &compute, nb::arg("kernel"), nb::arg("parameters") = nb::dict(),
           nb::arg("inputs") = nb::dict(), nb::arg("to_host") = true)
      .def("results", &results, nb::arg("kernel"), nb::arg("to_host"))
      .def("neighbours", &neighbours, nb::arg("half"), nb::arg("distances"), nb::arg("vectors"),
           nb::arg("to_host"), nb::arg("shifts") = false, nb::arg("any_row") = false)
      .def("pairs", &pairs, nb::arg("half"), nb::arg("distances"), nb::arg("vectors"),
           nb::arg("to_host"), nb::arg("shifts") = false, nb::arg("radii") = nb::none(),
           nb::arg("species") = nb::none(), nb::arg("table") = nb::none())
      .def("padded", &padded, nb::arg("k"), nb::arg("raise_on_overflow"), nb::arg("to_host"),
           nb::arg("shifts") = false, nb::arg("half") = false, nb::arg("nearest") = false)
      .def("timings",
           [](PyEngine& e) {
             const raycut::Timings t = locked(e, [](auto& x) { return x.last_timings(); });
             nb::dict d;
             d["build_ms"] = t.build_ms;
             d["compute_ms"] = t.compute_ms;
             d["device_build_ms"] = t.device_build_ms;
             d["device_compute_ms"] = t.device_compute_ms;
             d["refit"] = t.refit;
             return d;
           })
      .def(
          "_cpp_loop_us",
          [](PyEngine& locked_engine, nb::handle positions, double cutoff, std::string_view kernel,
             bool build, std::size_t calls) {
            // The C++ caller's loop (benchmarks: bench/python_overhead.py): `calls` times
            // [build] + run + results_view, each call timed on the host clock, no
            // Python in between. What a Python call's overhead is measured against.
            const FloatInput in = float_input(positions, "positions");
            const raycut::PositionsView view = positions_view(in);
            const raycut::Kernel k = raycut::parse_kernel(kernel);
            const float checked = raycut::checked_cutoff(cutoff);
            std::vector<double> us(calls);
            Exclusive hold(locked_engine.mutex);
            raycut::Engine& e = locked_engine.engine;
            for (double& t : us) {
              const auto start = std::chrono::steady_clock::now();
              if (build) e.build(view, checked);
              e.run(k);
              (void)e.results_view();  // run() returns synchronised
              t = std::chrono::duration<double, std::micro>(std::chrono::steady_clock::now() -
                                                            start)
                      .count();
            }
            return us;
          },
          nb::arg("positions"), nb::arg("cutoff"), nb::arg("kernel"), nb::arg("build"),
          nb::arg("calls"));
}

}  // namespace raycut_py
