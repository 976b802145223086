// Arrays in and out of the extension: positions and other float32 inputs read in place from
// NumPy, DLPack or __cuda_array_interface__ (dtype, device, shape and layout checked), the
// systems (boxes, batches, query points) the Python layer prepared, and the library's buffers
// wrapped as NumPy or DLPack arrays without a copy.
#pragma once

#include <nanobind/nanobind.h>
#include <nanobind/ndarray.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "raycut/engine.hpp"

namespace nb = nanobind;

namespace raycut_py {

using raycut::MemorySpace;

// ---- inputs ------------------------------------------------------------------------------------

// A float32 C-contiguous array read in place, on the host or the CUDA device.
struct FloatInput {
  const float* data = nullptr;
  std::vector<std::size_t> shape;
  MemorySpace space = MemorySpace::host;
  std::optional<nb::ndarray<nb::ro>> keep;  // the imported DLPack tensor, alive during the call
};

// "(N, 3)" for messages.
std::string describe_shape(const std::vector<std::size_t>& shape);

// `obj` (named `name` in messages) read in place: DLPack, or __cuda_array_interface__ without it.
FloatInput float_input(nb::handle obj, const char* name);

#if defined(RAYCUT_PY_CUDA)
// A 1-D int32 or int64 C-contiguous CUDA array, N >= 1 (a batch index).
struct DeviceIndex {
  const void* data = nullptr;
  std::size_t n = 0;
  bool wide = false;
  nb::ndarray<nb::ro> keep;
};

DeviceIndex device_index(nb::handle obj);
#endif

// Positions of shape (N, 3).
raycut::PositionsView positions_view(const FloatInput& in);

// ---- systems (boxes, batches, query points) ---------------------------------------------------

using HostCells = nb::ndarray<const double, nb::ndim<3>, nb::c_contig, nb::device::cpu>;
using HostFlags = nb::ndarray<const bool, nb::ndim<2>, nb::c_contig, nb::device::cpu>;
using HostOffsets = nb::ndarray<const std::uint64_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using HostDoubles = nb::ndarray<const double, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
using HostSpecies = nb::ndarray<const std::uint32_t, nb::ndim<1>, nb::c_contig, nb::device::cpu>;
// The caller's float64 positions on the host, beside their float32 rounding: the engine decides
// in double what that rounding could (raycut::Float64Positions).
using HostPositions64 = nb::ndarray<const double, nb::ndim<2>, nb::c_contig, nb::device::cpu>;

raycut::Float64Positions float64_positions(const HostPositions64& wide, std::size_t n);

// raycut::Systems from what the Python layer prepared: cells (B, 3, 3) float64 and pbc (B, 3)
// bool (B = 1: one box for every system), batch offsets, query points and their offsets. The
// query points are read in place: `queries` keeps them alive until build() returns.
raycut::Systems make_systems(const std::optional<HostCells>& cells,
                             const std::optional<HostFlags>& pbc,
                             const std::optional<HostOffsets>& offsets, nb::handle query_points,
                             const std::optional<HostOffsets>& query_offsets, FloatInput& queries);

// ---- outputs -----------------------------------------------------------------------------------

template <class T>
nb::dlpack::dtype dtype_of() {
  return nb::dtype<T>();
}

// Wraps `data` (shape, dtype) without a copy; `owner` keeps the memory alive for as long as any
// Python array (or a framework tensor imported from it through DLPack) refers to it.
nb::object wrap(const void* data, std::vector<std::size_t> shape, nb::dlpack::dtype dtype,
                std::shared_ptr<const void> owner, MemorySpace space);

// A host vector, moved into the array that owns it.
template <class T>
nb::object host_array(std::vector<T>&& values, std::vector<std::size_t> shape,
                      nb::dlpack::dtype dtype = dtype_of<T>()) {
  auto owner = std::make_shared<std::vector<T>>(std::move(values));
  return wrap(owner->data(), std::move(shape), dtype, owner, MemorySpace::host);
}

// Indices are uint32 in the library; int32 (the same bits) is what every framework indexes with.
nb::dlpack::dtype index_dtype(std::size_t n);

}  // namespace raycut_py
