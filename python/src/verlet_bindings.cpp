// The class VerletList: raycut::VerletList, its rules (cutoff, skin, the list's reach) checked
// here, and the arrays of each rebuild's list handed to Python.
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/string_view.h>

#include <cmath>
#include <cstdint>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <type_traits>
#include <vector>

#include "arrays.hpp"
#include "bindings.hpp"
#include "errors.hpp"

#if defined(RAYCUT_PY_CUDA)
#include "device.hpp"
#endif

namespace raycut_py {

namespace {

// raycut::VerletList with a snapshot of its list per rebuild. The library reuses (and overwrites)
// its list buffer at every rebuild, so the arrays handed to Python wrap a copy of it instead:
// made once per rebuild, on the first neighbours() call after it (on the device for device
// lists), and owned by the arrays' capsules, so arrays of an older list stay valid after a
// rebuild. Every neighbours() call between two rebuilds wraps the same snapshot.
struct Verlet {
  struct Snapshot {
    std::shared_ptr<const void> owner;
    const void* offsets = nullptr;
    const void* indices = nullptr;
    const float* distances = nullptr;
    const float* vectors = nullptr;
    const std::int32_t* shifts = nullptr;
    std::size_t n = 0;
    std::uint64_t pairs = 0;
    MemorySpace space = MemorySpace::host;
    std::uint64_t rebuild = 0;  // VerletList::rebuilds() when it was taken
    bool to_host = false;       // asked for on the host
  };

  raycut::VerletList list;
  raycut::ListOptions options;
  std::optional<Snapshot> snapshot;
  std::mutex mutex;  // serialises calls from Python threads (see Exclusive)

  Verlet(std::string_view method, float cutoff, float skin, raycut::ListOptions opts,
         const raycut::Systems& systems)
      : list(method, cutoff, skin, opts, systems), options(opts) {}
};

// Called with the Verlet's lock held and the GIL released: no Python here.
Verlet::Snapshot take_snapshot(Verlet& v, bool to_host) {
  const raycut::NeighbourListBuffer& list = v.list.list();
  Verlet::Snapshot s;
  s.n = list.size();
  s.pairs = list.pairs();
  s.rebuild = v.list.rebuilds();
  s.to_host = to_host;
  if (list.space() == MemorySpace::host || to_host) {
    auto host = std::make_shared<raycut::NeighbourList>(list.to_host());
    s.offsets = host->offsets.data();
    s.indices = host->indices.data();
    s.distances = host->distances.empty() ? nullptr : host->distances.data();
    s.vectors = host->vectors.empty() ? nullptr : host->vectors.data();
    s.shifts = host->shifts.empty() ? nullptr : host->shifts.data();
    s.space = MemorySpace::host;
    s.owner = host;
    return s;
  }
#if defined(RAYCUT_PY_CUDA)
  // One allocation per array (each aligned as its own allocation, as some consumers want),
  // freed with the last array that refers to any of them.
  struct DeviceCopies {
    std::vector<void*> blocks;
    ~DeviceCopies() {
      for (void* p : blocks) raycut_py::device_free(p);
    }
  };
  auto copies = std::make_shared<DeviceCopies>();
  auto copy = [&](const void* src, std::size_t bytes) -> const void* {
    if (src == nullptr) return nullptr;
    void* dst = raycut_py::device_alloc(bytes);
    copies->blocks.push_back(dst);
    raycut_py::device_copy(dst, src, bytes, v.list.engine().stream());
    return dst;
  };
  s.offsets = copy(list.offsets(), (s.n + 1) * sizeof(std::uint64_t));
  s.indices = copy(list.indices(), s.pairs * sizeof(std::uint32_t));
  if (v.options.distances)
    s.distances = static_cast<const float*>(copy(list.distances(), s.pairs * sizeof(float)));
  if (v.options.vectors)
    s.vectors = static_cast<const float*>(copy(list.vectors(), 3 * s.pairs * sizeof(float)));
  if (v.options.shifts)
    s.shifts =
        static_cast<const std::int32_t*>(copy(list.shifts(), 3 * s.pairs * sizeof(std::int32_t)));
  raycut_py::synchronize(v.list.engine().stream());
  s.space = MemorySpace::device;
  s.owner = copies;
  return s;
#else
  throw raycut::Error(raycut::ErrorCode::internal, "device list without CUDA");
#endif
}

// CSR of the last rebuild, as Engine.neighbours returns it: (offsets int64 [N+1], indices int32
// [P], distances [P] or None, vectors [P, 3] or None, shifts int32 [P, 3] or None).
nb::tuple verlet_neighbours(Verlet& v, bool to_host) {
  Verlet::Snapshot s;
  {
    Exclusive hold(v.mutex);
    if (v.list.rebuilds() == 0)
      value_error("VerletList.neighbours(): no list yet, call update(positions) first");
    if (!v.snapshot || v.snapshot->rebuild != v.list.rebuilds() || v.snapshot->to_host != to_host)
      v.snapshot = take_snapshot(v, to_host);
    s = *v.snapshot;
  }
  const std::size_t pairs = s.pairs;
  auto opt = [&](bool asked, const auto* data, std::vector<std::size_t> shape) -> nb::object {
    using T = std::remove_cv_t<std::remove_pointer_t<decltype(data)>>;
    if (!asked) return nb::none();
    return wrap(data, std::move(shape), dtype_of<T>(), s.owner, s.space);
  };
  return nb::make_tuple(wrap(s.offsets, {s.n + 1}, dtype_of<std::int64_t>(), s.owner, s.space),
                        wrap(s.indices, {pairs}, index_dtype(s.n), s.owner, s.space),
                        opt(v.options.distances, s.distances, {pairs}),
                        opt(v.options.vectors, s.vectors, {pairs, 3}),
                        opt(v.options.shifts, s.shifts, {pairs, 3}));
}

}  // namespace

void bind_verlet(nb::module_& m) {
  nb::class_<Verlet>(m, "VerletList")
      .def(
          "__init__",
          [](Verlet* self, double cutoff, double skin, std::string_view method, bool half,
             bool distances, bool vectors, bool shifts, const std::optional<HostCells>& cells,
             const std::optional<HostFlags>& pbc, const std::optional<HostOffsets>& offsets) {
            const float checked = raycut::checked_cutoff(cutoff);  // as given, then float
            if (!std::isfinite(skin) || !(skin >= 0))
              value_error("skin must be finite and >= 0, got " + number(skin));
            try {
              raycut::checked_cutoff(cutoff + skin);  // the list's reach, also as given
            } catch (const raycut::Error& e) {
              value_error(std::string("cutoff + skin (the list's reach): ") + e.what());
            }
            FloatInput no_queries;
            const raycut::Systems systems =
                make_systems(cells, pbc, offsets, nb::none(), std::nullopt, no_queries);
            new (self) Verlet(method, checked, static_cast<float>(skin),
                              raycut::ListOptions{half, distances, vectors, shifts}, systems);
          },
          nb::arg("cutoff"), nb::arg("skin"), nb::arg("method") = "auto", nb::arg("half") = false,
          nb::arg("distances") = false, nb::arg("vectors") = false, nb::arg("shifts") = false,
          nb::arg("cells").none() = nb::none(), nb::arg("pbc").none() = nb::none(),
          nb::arg("offsets").none() = nb::none())
      .def_prop_ro("method", [](Verlet& v) { return v.list.engine().method(); })
      .def_prop_ro("space", [](Verlet& v) { return space_name(v.list.engine().space()); })
      .def_prop_ro("size",
                   [](Verlet& v) {
                     Exclusive hold(v.mutex);
                     return v.list.engine().size();
                   })
      .def_prop_ro("cutoff", [](const Verlet& v) { return v.list.cutoff(); })
      .def_prop_ro("skin", [](const Verlet& v) { return v.list.skin(); })
      .def_prop_ro("rebuilds",
                   [](Verlet& v) {
                     Exclusive hold(v.mutex);
                     return v.list.rebuilds();
                   })
      .def_prop_ro("half", [](const Verlet& v) { return v.options.half; })
      .def_prop_ro("distances", [](const Verlet& v) { return v.options.distances; })
      .def_prop_ro("vectors", [](const Verlet& v) { return v.options.vectors; })
      .def_prop_ro("shifts", [](const Verlet& v) { return v.options.shifts; })
      .def(
          "set_stream",
          [](Verlet& v, std::uintptr_t stream) {
            Exclusive hold(v.mutex);
            v.list.engine().set_stream(reinterpret_cast<void*>(stream));
          },
          nb::arg("stream"))
      .def(
          "update",
          [](Verlet& v, nb::handle positions) {
            const FloatInput in = float_input(positions, "positions");
            const raycut::PositionsView view = positions_view(in);
            Exclusive hold(v.mutex);
            return v.list.update(view);
          },
          nb::arg("positions"))
      .def("neighbours", &verlet_neighbours, nb::arg("to_host"));
}

}  // namespace raycut_py
