// pyraycut._raycut: the nanobind extension under the pyraycut Python package (python/pyraycut). It
// reads positions from anything with DLPack (NumPy, PyTorch, CuPy, JAX) or
// __cuda_array_interface__, without a copy, and returns arrays that wrap the library's own
// buffers (a capsule keeps them alive): NumPy arrays on the host, DLPack-capable arrays on the
// device that the Python layer hands to the caller's framework (from_dlpack, zero-copy).
#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>
#include <nanobind/stl/optional.h>
#include <nanobind/stl/string.h>
#include <nanobind/stl/string_view.h>
#include <nanobind/stl/vector.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <deque>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "raycut/engine.hpp"
#include "raycut/error.hpp"
#include "raycut/kernels.hpp"
#include "raycut/tools/device_array.hpp"

#if defined(RAYCUT_PY_CUDA)
#include "device.hpp"
#endif

namespace nb = nanobind;
using raycut::MemorySpace;

namespace {

PyObject* capacity_error = nullptr;  // raycut.CapacityError(RuntimeError)

[[noreturn]] void value_error(const std::string& message) {
  throw raycut::Error(raycut::ErrorCode::invalid_argument, message);
}

// ---- threads -----------------------------------------------------------------------------------

// Calls on one Engine or VerletList from several Python threads are serialised by the object's
// mutex; calls on different objects run in parallel (the GIL is released while the library
// works). The GIL is released before the mutex is taken, and taken again only after the mutex
// is released: a thread never waits for the mutex while holding the GIL, nor for the GIL while
// holding the mutex, so the two cannot deadlock.
struct Exclusive {
  nb::gil_scoped_release release;  // first: released before locking, taken after unlocking
  std::lock_guard<std::mutex> lock;
  explicit Exclusive(std::mutex& mutex) : lock(mutex) {}
};

// raycut::Engine with its lock (what the Python class Engine holds).
struct PyEngine {
  raycut::Engine engine;
  std::mutex mutex;
  explicit PyEngine(std::string_view method) : engine(method) {}
};

// A value of the engine read under its lock.
template <class F>
auto locked(PyEngine& e, F&& read) {
  Exclusive hold(e.mutex);
  return read(e.engine);
}

// ---- inputs ------------------------------------------------------------------------------------

// A float32 C-contiguous array read in place, on the host or the CUDA device.
struct FloatInput {
  const float* data = nullptr;
  std::vector<std::size_t> shape;
  MemorySpace space = MemorySpace::host;
  std::optional<nb::ndarray<nb::ro>> keep;  // the imported DLPack tensor, alive during the call
};

// A value in messages ("1e-50", "0.25").
std::string number(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", value);
  return text;
}

std::string describe_shape(const std::vector<std::size_t>& shape) {
  std::string s = "(";
  for (std::size_t d = 0; d < shape.size(); ++d) s += (d ? ", " : "") + std::to_string(shape[d]);
  return s + (shape.size() == 1 ? ",)" : ")");
}

std::string describe_dtype(nb::dlpack::dtype dt) {
  const char* kind = "?";
  switch (static_cast<nb::dlpack::dtype_code>(dt.code)) {
    case nb::dlpack::dtype_code::Int:
      kind = "int";
      break;
    case nb::dlpack::dtype_code::UInt:
      kind = "uint";
      break;
    case nb::dlpack::dtype_code::Float:
      kind = "float";
      break;
    case nb::dlpack::dtype_code::Bfloat:
      kind = "bfloat";
      break;
    case nb::dlpack::dtype_code::Complex:
      kind = "complex";
      break;
    case nb::dlpack::dtype_code::Bool:
      kind = "bool";
      break;
  }
  return kind + std::to_string(dt.bits);
}

// __cuda_array_interface__ (version 2 or 3) of an object without DLPack (e.g. Numba's arrays).
FloatInput from_cuda_array_interface(nb::handle obj, const char* name) {
  nb::dict cai = nb::cast<nb::dict>(obj.attr("__cuda_array_interface__"));
  FloatInput in;
  in.space = MemorySpace::device;
  for (nb::handle d : nb::cast<nb::tuple>(cai["shape"]))
    in.shape.push_back(nb::cast<std::size_t>(d));
  const std::string typestr = nb::cast<std::string>(cai["typestr"]);
  if (typestr != "<f4")
    value_error(std::string(name) + " must be float32 C-contiguous on the device, got typestr '" +
                typestr + "' (convert it in your framework first)");
  if (cai.contains("mask") && !cai["mask"].is_none())
    value_error(std::string(name) + ": masked arrays are not supported");
  if (cai.contains("strides") && !cai["strides"].is_none()) {
    nb::tuple strides = nb::cast<nb::tuple>(cai["strides"]);
    std::size_t expected = 4;
    for (std::size_t d = in.shape.size(); d-- > 0;) {
      if (in.shape[d] > 1 && nb::cast<std::size_t>(strides[d]) != expected)
        value_error(std::string(name) + " must be C-contiguous (device arrays are read in place)");
      expected *= in.shape[d];
    }
  }
  nb::tuple data = nb::cast<nb::tuple>(cai["data"]);
  in.data = reinterpret_cast<const float*>(nb::cast<std::uintptr_t>(data[0]));
  return in;
}

FloatInput float_input(nb::handle obj, const char* name) {
  nb::ndarray<nb::ro> array;
  if (!nb::try_cast(obj, array, /*convert=*/false)) {
    if (nb::hasattr(obj, "__cuda_array_interface__")) return from_cuda_array_interface(obj, name);
    throw nb::type_error((std::string(name) +
                          " must be a NumPy array or an array with __dlpack__ or "
                          "__cuda_array_interface__, got " +
                          nb::cast<std::string>(nb::str(obj.type())))
                             .c_str());
  }
  FloatInput in;
  for (std::size_t d = 0; d < array.ndim(); ++d) in.shape.push_back(array.shape(d));
  const int device = array.device_type();
  if (device == nb::device::cpu::value || device == nb::device::cuda_host::value)
    in.space = MemorySpace::host;
  else if (device == nb::device::cuda::value || device == nb::device::cuda_managed::value)
    in.space = MemorySpace::device;
  else
    value_error(std::string(name) + " is on an unsupported device (DLPack device type " +
                std::to_string(device) + "): raycut reads the host and CUDA devices");
  if (array.dtype() != nb::dtype<float>())
    value_error(std::string(name) + " must be float32, got " + describe_dtype(array.dtype()) +
                (in.space == MemorySpace::device ? " (device arrays are read in place: convert "
                                                   "them in your framework first)"
                                                 : ""));
  std::int64_t expected = 1;
  const bool empty = array.size() == 0;  // no elements: strides mean nothing
  for (std::size_t d = array.ndim(); !empty && d-- > 0;) {
    if (array.shape(d) > 1 && array.stride(d) != expected)
      value_error(std::string(name) + " must be C-contiguous (arrays are read in place)");
    expected *= static_cast<std::int64_t>(array.shape(d));
  }
  in.data = static_cast<const float*>(array.data());
  in.keep = std::move(array);
  return in;
}

#if defined(RAYCUT_PY_CUDA)
// A 1-D int32 or int64 C-contiguous CUDA array, N >= 1 (a batch index).
struct DeviceIndex {
  const void* data = nullptr;
  std::size_t n = 0;
  bool wide = false;
  nb::ndarray<nb::ro> keep;
};

DeviceIndex device_index(nb::handle obj) {
  DeviceIndex in;
  if (!nb::try_cast(obj, in.keep, /*convert=*/false) ||
      in.keep.device_type() != nb::device::cuda::value || in.keep.ndim() != 1 ||
      in.keep.shape(0) == 0 || (in.keep.shape(0) > 1 && in.keep.stride(0) != 1) ||
      (in.keep.dtype() != nb::dtype<std::int32_t>() &&
       in.keep.dtype() != nb::dtype<std::int64_t>()))
    value_error(
        "a system index on the device must be a non-empty 1-D contiguous int32 or int64 "
        "CUDA array");
  in.data = in.keep.data();
  in.n = in.keep.shape(0);
  in.wide = in.keep.dtype() == nb::dtype<std::int64_t>();
  return in;
}
#endif

raycut::PositionsView positions_view(const FloatInput& in) {
  if (in.shape.size() != 2 || in.shape[1] != 3)
    value_error("positions must have shape (N, 3), got " + describe_shape(in.shape));
  return {in.data, in.shape[0], in.space};
}

// ---- systems (boxes, batches, query points) ---------------------------------------------------

using HostCells = nb::ndarray<const double, nb::ndim<3>, nb::c_contig, nb::device::cpu>;
using HostFlags = nb::ndarray<const bool, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using HostOffsets = nb::ndarray<const std::uint64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
// The caller's float64 positions on the host, beside their float32 rounding: the engine decides
// in double what that rounding could (raycut::Float64Positions).
using HostPositions64 = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;

raycut::Float64Positions float64_positions(const HostPositions64& wide, std::size_t n) {
  if (wide.shape(0) != n || wide.shape(1) != 3)
    value_error("positions64 must have shape (" + std::to_string(n) + ", 3)");
  return {wide.data(), n};
}

// raycut::Systems from what the Python layer prepared: cells (B, 3, 3) float64 and pbc (B, 3)
// bool (B = 1: one box for every system), batch offsets, query points and their offsets. The
// query points are read in place: `queries` keeps them alive until build() returns.
raycut::Systems make_systems(const std::optional<HostCells>& cells,
                             const std::optional<HostFlags>& pbc,
                             const std::optional<HostOffsets>& offsets, nb::handle query_points,
                             const std::optional<HostOffsets>& query_offsets, FloatInput& queries) {
  raycut::Systems systems;
  if (cells.has_value() != pbc.has_value())
    value_error("cells and pbc go together (the raycut package passes both)");
  if (cells) {
    const std::size_t count = cells->shape(0);
    if (cells->shape(1) != 3 || cells->shape(2) != 3 || pbc->shape(0) != count ||
        pbc->shape(1) != 3)
      value_error("cells must have shape (B, 3, 3) and pbc (B, 3), got cells (" +
                  std::to_string(cells->shape(0)) + ", " + std::to_string(cells->shape(1)) + ", " +
                  std::to_string(cells->shape(2)) + ") and pbc (" + std::to_string(pbc->shape(0)) +
                  ", " + std::to_string(pbc->shape(1)) + ")");
    std::vector<raycut::Box> boxes(count);
    for (std::size_t b = 0; b < count; ++b)
      for (int r = 0; r < 3; ++r) {
        boxes[b].pbc[r] = (*pbc)(b, r);
        for (int c = 0; c < 3; ++c) boxes[b].cell[r][c] = (*cells)(b, r, c);
      }
    if (count == 1)
      systems.box = boxes[0];
    else
      systems.boxes = std::move(boxes);
  }
  if (offsets) systems.offsets.assign(offsets->data(), offsets->data() + offsets->shape(0));
  if (!query_points.is_none()) {
    queries = float_input(query_points, "queries");
    if (queries.shape.size() != 2 || queries.shape[1] != 3)
      value_error("queries must have shape (M, 3), got " + describe_shape(queries.shape));
    // No query points is still a query set (no pairs), not "no queries": a non-null pointer.
    static const float none[3] = {0, 0, 0};
    systems.queries = {queries.data != nullptr ? queries.data : none, queries.shape[0],
                       queries.space};
    if (query_offsets)
      systems.query_offsets.assign(query_offsets->data(),
                                   query_offsets->data() + query_offsets->shape(0));
  } else if (query_offsets) {
    value_error("query offsets without query points");
  }
  return systems;
}

// ---- outputs -----------------------------------------------------------------------------------

template <class T>
nb::dlpack::dtype dtype_of() {
  return nb::dtype<T>();
}

// Wraps `data` (shape, dtype) without a copy; `owner` keeps the memory alive for as long as any
// Python array (or a framework tensor imported from it through DLPack) refers to it.
nb::object wrap(const void* data, std::vector<std::size_t> shape, nb::dlpack::dtype dtype,
                std::shared_ptr<const void> owner, MemorySpace space) {
  std::size_t elements = 1;
  for (std::size_t s : shape) elements *= s;
  int device_id = 0;
  if (space == MemorySpace::device) {
#if defined(RAYCUT_PY_CUDA)
    device_id = raycut_py::current_device();
    if (data == nullptr || elements == 0) {  // empty: a valid pointer all the same
      void* p = raycut_py::device_alloc(16);
      owner = std::shared_ptr<const void>(
          p, [](const void* q) { raycut_py::device_free(const_cast<void*>(q)); });
      data = p;
    }
#else
    throw raycut::Error(raycut::ErrorCode::internal, "device output without CUDA");
#endif
  } else if (data == nullptr || elements == 0) {
    static const std::uint64_t empty[2] = {0, 0};
    data = empty;
  }
  auto* held = new std::shared_ptr<const void>(std::move(owner));
  nb::capsule capsule(
      held, [](void* p) noexcept { delete static_cast<std::shared_ptr<const void>*>(p); });
  void* ptr = const_cast<void*>(data);
  if (space == MemorySpace::host)
    return nb::cast(nb::ndarray<nb::numpy>(ptr, shape.size(), shape.data(), capsule, nullptr, dtype,
                                           nb::device::cpu::value, 0));
  return nb::cast(nb::ndarray<>(ptr, shape.size(), shape.data(), capsule, nullptr, dtype,
                                nb::device::cuda::value, device_id));
}

// A host vector, moved into the array that owns it.
template <class T>
nb::object host_array(std::vector<T>&& values, std::vector<std::size_t> shape,
                      nb::dlpack::dtype dtype = dtype_of<T>()) {
  auto owner = std::make_shared<std::vector<T>>(std::move(values));
  return wrap(owner->data(), std::move(shape), dtype, owner, MemorySpace::host);
}

// Indices are uint32 in the library; int32 (the same bits) is what every framework indexes with.
nb::dlpack::dtype index_dtype(std::size_t n) {
  return n <= static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max())
             ? dtype_of<std::int32_t>()
             : dtype_of<std::uint32_t>();
}

// The list of `engine`'s positions where the method works (a new buffer: earlier results stay
// valid).
std::shared_ptr<raycut::NeighbourListBuffer> fill_list(PyEngine& e, bool half, bool distances,
                                                       bool vectors, bool shifts,
                                                       bool coo = false) {
  auto list = std::make_shared<raycut::NeighbourListBuffer>();
  Exclusive hold(e.mutex);
  e.engine.neighbours(*list, raycut::ListOptions{half, distances, vectors, shifts, coo});
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
                     bool shifts) {
  const ListArrays a = arrays_of(fill_list(engine, half, distances, vectors, shifts), to_host);
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
                bool shifts) {
  const ListArrays a =
      arrays_of(fill_list(engine, half, distances, vectors, shifts, /*coo=*/true), to_host);
  const std::size_t count = a.pairs;
  return nb::make_tuple(a.optional(true, a.rows, {count}), a.optional(true, a.columns, {count}),
                        a.optional(distances, a.distances, {count}),
                        a.optional(vectors, a.vectors, {count, 3}),
                        a.optional(shifts, a.shifts, {count, 3}));
}

// Padded [N, K] (int32; N marks an empty slot), counts [N] (int32), report, and with `shifts`
// S [N, K, 3] (int32; 0 in empty slots).
nb::tuple padded(PyEngine& engine, std::uint64_t wide_k, bool raise_on_overflow, bool to_host,
                 bool shifts, bool half) {
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
    report = engine.engine.padded_neighbours(
        *list, {.k = k, .half = half, .shifts = shifts, .throw_on_overflow = raise_on_overflow});
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

// The results of the last run() of a kernel, taken out of the engine under its lock: host
// copies of device results (`to_host`), or the engine's own arrays moved out (no copy: a later
// run() sizes new ones, so these stay as they are).
struct TakenResults {
  std::size_t n = 0;
  MemorySpace space = MemorySpace::host;
  bool copied = false;
  raycut::Results copies;
  raycut::OwnedResults owned;
};

TakenResults take_results(raycut::Engine& engine, bool to_host) {  // the lock held
  TakenResults taken;
  taken.n = engine.size();
  taken.space = engine.space();
  taken.copied = taken.space == MemorySpace::device && to_host;
  if (taken.copied)
    taken.copies = engine.results();
  else
    taken.owned = engine.take_results();
  return taken;
}

// The arrays `kernel` produces (raycut::produces), empty ones for N = 0; with the GIL.
nb::dict results_dict(TakenResults& t, raycut::Kernel kernel) {
  const raycut::KernelProduces produces = raycut::produces(kernel);
  const std::size_t n = t.n;
  nb::dict out;
  if (t.copied) {
    raycut::Results& r = t.copies;
    if (produces.count) out["count"] = host_array(std::move(r.count), {n}, index_dtype(n));
    if (produces.energy) out["energy"] = host_array(std::move(r.energy), {n});
    if (produces.force) out["force"] = host_array(std::move(r.force), {n, 3});
    if (produces.virial) out["virial"] = host_array(std::move(r.virial), {n, 6});
    if (produces.density) out["density"] = host_array(std::move(r.density), {n});
    return out;
  }
  const raycut::ResultsView& v = t.owned.view;
  auto put = [&](const char* name, const void* data, std::vector<std::size_t> shape,
                 nb::dlpack::dtype dtype) {
    out[name] = wrap(data, std::move(shape), dtype, t.owned.owner, t.space);
  };
  if (produces.count) put("count", v.count, {n}, index_dtype(n));
  if (produces.energy) put("energy", v.energy, {n}, dtype_of<float>());
  if (produces.force) put("force", v.force, {n, 3}, dtype_of<float>());
  if (produces.virial) put("virial", v.virial, {n, 6}, dtype_of<float>());
  if (produces.density) put("density", v.density, {n}, dtype_of<float>());
  return out;
}

nb::dict results(PyEngine& locked_engine, std::string_view kernel_name, bool to_host) {
  const raycut::Kernel kernel = raycut::parse_kernel(kernel_name);
  TakenResults taken;
  {
    Exclusive hold(locked_engine.mutex);
    taken = take_results(locked_engine.engine, to_host);
  }
  return results_dict(taken, kernel);
}

// A per-particle float input of a kernel (raycut::KernelInput: sph_force's velocity, density,
// pressure, coulomb_dsf's charge) where the method works: read in place there, copied to the
// device (raycut::DeviceArray) from the host. `source` is read with the GIL held; the rest
// (checked against the engine's size) under the engine's lock, since another thread may build
// it with another N in between.
struct KernelInput {
  const raycut::KernelInput* spec = nullptr;
  const float* data = nullptr;
  std::optional<raycut::DeviceArray> device_copy;
  FloatInput source;
};

void check_kernel_input(KernelInput& out, const raycut::Engine& engine) {
  const raycut::KernelInput& spec = *out.spec;
  const std::string name(spec.name);
  // One value (or vector) per source, or per target: the targets are the queries with query
  // points, the sources otherwise.
  const std::size_t n = spec.end == raycut::InputEnd::sources ? engine.sources() : engine.size();
  const std::size_t components = spec.components;
  const std::vector<std::size_t>& shape = out.source.shape;
  const bool ok = components > 1 ? shape.size() == 2 && shape[0] == n && shape[1] == components
                                 : shape.size() == 1 && shape[0] == n;
  const char* per = spec.end == raycut::InputEnd::queries ? " per query" : " per particle";
  if (!ok)
    value_error(name + " must have shape " +
                (components > 1 ? "(" + std::to_string(n) + ", " + std::to_string(components) + ")"
                                : "(" + std::to_string(n) + ",)") +
                " (one " + (components > 1 ? "vector" : "value") + per + "), got " +
                describe_shape(shape));
  out.data = out.source.data;
  if (out.source.space == MemorySpace::host) {
    // Host values are checked here (device ones are read in place, unchecked): a zero or
    // non-finite density, a non-finite pressure, velocity or charge gives non-finite results.
    for (std::size_t k = 0; k < n * components; ++k) {
      const float value = out.data[k];
      if (!std::isfinite(value) || (spec.positive && !(value > 0.0f)))
        value_error(name + "[" + std::to_string(k / components) + "] = " + number(value) +
                    (spec.positive ? ": must be finite and > 0" : ": must be finite"));
    }
  }
  if (out.source.space == engine.space()) return;
  if (engine.space() == MemorySpace::host)
    value_error(name + " is in device memory but method '" + engine.method() +
                "' works on the host: pass it on the host");
  out.device_copy.emplace(std::vector<float>(out.data, out.data + n * components));
  out.data = out.device_copy->data();
}

// Sets the parameter `name` (of any built-in kernel: one call may pass every kernel's) in options.
void set_kernel_parameter(raycut::KernelOptions& options, const std::string& name,
                          nb::handle value) {
  bool found = false;
  std::vector<std::string_view> known;  // each name once (kernels share parameters)
  raycut::for_each_kernel([&](auto spec) {
    for (const raycut::KernelParameter& p : decltype(spec)::parameters) {
      if (std::find(known.begin(), known.end(), p.name) == known.end()) known.push_back(p.name);
      if (found || p.name != name) continue;
      found = true;
      if (p.flag)
        options.*p.flag = nb::cast<bool>(value);
      else
        options.*p.value = nb::cast<float>(value);
    }
  });
  if (found) return;
  std::string list;
  for (std::string_view k : known) list += (list.empty() ? "" : ", ") + std::string(k);
  value_error("unknown kernel parameter '" + name + "' (known: " + list + ")");
}

// run() and its results in one locked call: another thread's run() in between would take them.
// `parameters` maps parameter names to numbers (or flags), `inputs` input names to arrays
// (raycut's kernel catalogue, kernel_catalogue()).
nb::dict compute(PyEngine& locked_engine, std::string_view kernel_name, nb::dict parameters,
                 nb::dict inputs, bool to_host) {
  const raycut::Kernel kernel = raycut::parse_kernel(kernel_name);
  raycut::KernelOptions options;
  for (auto [key, value] : parameters)
    set_kernel_parameter(options, nb::cast<std::string>(key), value);
  std::deque<KernelInput> given;  // stable addresses, no moves
  raycut::visit_kernel(kernel, [&](auto spec) {
    using Spec = decltype(spec);
    for (auto [key, value] : inputs) {
      const std::string name = nb::cast<std::string>(key);
      const raycut::KernelInput* found = nullptr;
      std::string known;
      for (const raycut::KernelInput& input : Spec::inputs) {
        if (input.name == name) found = &input;
        known += (known.empty() ? "" : ", ") + std::string(input.name);
      }
      if (!found)
        value_error("kernel " + std::string(Spec::name) + " reads no input '" + name +
                    "' (its inputs: " + (known.empty() ? "none" : known) + ")");
      if (value.is_none()) continue;
      KernelInput& in = given.emplace_back();
      in.spec = found;
      in.source = float_input(value, found->name.data());
    }
  });
  TakenResults taken;
  {
    Exclusive hold(locked_engine.mutex);
    raycut::Engine& engine = locked_engine.engine;
    for (KernelInput& in : given) {
      check_kernel_input(in, engine);
      in.spec->field(options) = in.data;
    }
    engine.run(kernel, options);
    taken = take_results(engine, to_host);
  }
  return results_dict(taken, kernel);
}

// The built-in kernels (raycut's catalogue), in a stable order: per kernel its name, its
// parameters (name, type "float" or "bool", default, accepted [min, max]), its per-particle
// inputs (name, components, end: "both", "sources" or "queries", positive) and its outputs
// (name, components).
nb::list kernel_catalogue() {
  nb::list out;
  const raycut::KernelOptions defaults;
  raycut::for_each_kernel([&](auto spec) {
    using Spec = decltype(spec);
    nb::list parameters, inputs, outputs;
    for (const raycut::KernelParameter& p : Spec::parameters) {
      nb::dict d;
      d["name"] = std::string(p.name);
      d["type"] = p.flag ? "bool" : "float";
      if (p.flag)
        d["default"] = defaults.*p.flag;
      else
        d["default"] = static_cast<double>(defaults.*p.value);
      d["min"] = p.min;
      d["max"] = p.max;
      parameters.append(d);
    }
    for (const raycut::KernelInput& in : Spec::inputs) {
      nb::dict d;
      d["name"] = std::string(in.name);
      d["components"] = in.components;
      d["end"] = in.end == raycut::InputEnd::both
                     ? "both"
                     : (in.end == raycut::InputEnd::sources ? "sources" : "queries");
      d["positive"] = in.positive;
      inputs.append(d);
    }
    for (const raycut::KernelOutputField& field : raycut::kernel_output_fields)
      if (Spec::outputs.*field.produced)
        outputs.append(nb::make_tuple(std::string(field.name), field.components));
    nb::dict k;
    k["name"] = std::string(Spec::name);
    k["parameters"] = parameters;
    k["inputs"] = inputs;
    k["outputs"] = outputs;
    out.append(k);
  });
  return out;
}

// ---- Verlet list ------------------------------------------------------------------------------

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

const char* space_name(MemorySpace space) {
  return space == MemorySpace::host ? "host" : "device";
}

}  // namespace

NB_MODULE(_raycut, m) {
  m.doc() = "raycut's C++ engine (nanobind); use the raycut package, not this module directly.";

  capacity_error = PyErr_NewExceptionWithDoc(
      "raycut.CapacityError",
      "A fixed-size output (the padded neighbour list) is too small: grow it and retry.",
      PyExc_RuntimeError, nullptr);
  m.attr("CapacityError") = nb::handle(capacity_error);

  // raycut::Error -> the Python exception of its code, with the library's message.
  nb::register_exception_translator([](const std::exception_ptr& p, void*) {
    try {
      std::rethrow_exception(p);
    } catch (const raycut::Error& e) {
      PyObject* type = PyExc_RuntimeError;
      switch (e.code()) {
        case raycut::ErrorCode::invalid_argument:
        case raycut::ErrorCode::invalid_input:
          type = PyExc_ValueError;
          break;
        case raycut::ErrorCode::out_of_memory:
          type = PyExc_MemoryError;
          break;
        case raycut::ErrorCode::unsupported:
          type = PyExc_NotImplementedError;
          break;
        case raycut::ErrorCode::io:
          type = PyExc_OSError;
          break;
        case raycut::ErrorCode::capacity_exceeded:
          type = capacity_error;
          break;
        case raycut::ErrorCode::backend:
        case raycut::ErrorCode::internal:
          type = PyExc_RuntimeError;
          break;
      }
      PyErr_SetString(type, e.what());
    }
  });

  m.def(
      "methods",
      [] {
        nb::list out;
        for (const auto& d : raycut::list_methods()) {
          nb::dict row;
          row["name"] = d.name;
          row["summary"] = d.summary;
          row["available"] = d.available;
          row["why"] = d.why_unavailable;
          out.append(row);
        }
        return out;
      },
      "Every method raycut knows, available here or not.");
  m.def("kernel_catalogue", &kernel_catalogue,
        "The built-in kernels: name, parameters, per-particle inputs and outputs of each.");
  m.def("auto_method", &raycut::auto_method, "What method='auto' picks on this machine.");
  m.def("cuda_device_available", &raycut::cuda_device_available);
  m.def(
      "current_device",
      [] {
#if defined(RAYCUT_PY_CUDA)
        return raycut_py::current_device_or_none();
#else
        return -1;
#endif
      },
      "The CUDA device current in this thread (where a GPU method allocates), -1 without one.");
  m.attr("has_cuda") =
#if defined(RAYCUT_PY_CUDA)
      true;
#else
      false;
#endif

#if defined(RAYCUT_PY_CUDA)
  // batch= as a CUDA tensor: checked and turned into offsets on the device (python/pyraycut/
  // _systems.py), only a summary and the offsets read back.
  m.def(
      "device_index_summary",
      [](nb::handle index, std::uintptr_t stream) {
        const DeviceIndex in = device_index(index);
        raycut_py::IndexSummary s;
        {
          nb::gil_scoped_release release;
          s = raycut_py::summarise_index(in.data, in.wide, in.n, reinterpret_cast<void*>(stream));
        }
        return nb::make_tuple(s.first, s.last, s.unsorted, s.here, s.after);
      },
      nb::arg("index"), nb::arg("stream"),
      "(first, last, k, index[k], index[k + 1]) of a 1-D int32/int64 CUDA array of N >= 1 "
      "entries: k the first place it decreases (N - 1 when sorted).");
  m.def(
      "device_index_offsets",
      [](nb::handle index, std::size_t systems, std::uintptr_t stream) {
        const DeviceIndex in = device_index(index);
        std::vector<std::uint64_t> offsets(systems + 1);
        {
          nb::gil_scoped_release release;
          raycut_py::index_offsets(in.data, in.wide, in.n, systems, offsets.data(),
                                   reinterpret_cast<void*>(stream));
        }
        return host_array(std::move(offsets), {systems + 1});
      },
      nb::arg("index"), nb::arg("systems"), nb::arg("stream"),
      "Systems offsets (S + 1, uint64) of a sorted 1-D int32/int64 CUDA index with values in "
      "[0, S).");
#endif

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
           nb::arg("to_host"), nb::arg("shifts") = false)
      .def("pairs", &pairs, nb::arg("half"), nb::arg("distances"), nb::arg("vectors"),
           nb::arg("to_host"), nb::arg("shifts") = false)
      .def("padded", &padded, nb::arg("k"), nb::arg("raise_on_overflow"), nb::arg("to_host"),
           nb::arg("shifts") = false, nb::arg("half") = false)
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
