#include "arrays.hpp"

#include <nanobind/stl/string.h>

#include <cstring>
#include <limits>

#include "errors.hpp"

#if defined(RAYCUT_PY_CUDA)
#include "device.hpp"
#endif

namespace raycut_py {

namespace {

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

}  // namespace

std::string describe_shape(const std::vector<std::size_t>& shape) {
  std::string s = "(";
  for (std::size_t d = 0; d < shape.size(); ++d) s += (d ? ", " : "") + std::to_string(shape[d]);
  return s + (shape.size() == 1 ? ",)" : ")");
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

raycut::Float64Positions float64_positions(const HostPositions64& wide, std::size_t n) {
  if (wide.shape(0) != n || wide.shape(1) != 3)
    value_error("positions64 must have shape (" + std::to_string(n) + ", 3)");
  return {wide.data(), n};
}

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

nb::dlpack::dtype index_dtype(std::size_t n) {
  return n <= static_cast<std::size_t>(std::numeric_limits<std::int32_t>::max())
             ? dtype_of<std::int32_t>()
             : dtype_of<std::uint32_t>();
}

}  // namespace raycut_py
