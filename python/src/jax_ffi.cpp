// raycut's neighbour list as an XLA FFI custom call on the CPU (raycut.jax, python/raycut/jax.py):
// static-capacity outputs, so that it runs inside jax.jit. Built as its own shared library,
// raycut/_jax_ffi.so, against the FFI headers jaxlib ships (jax.ffi.include_dir()); the Python
// side registers the handler symbol with jax.ffi.register_ffi_target.
//
// Inputs: positions (N, 3) float32; cell (3, 3) float32 or float64; pbc (3,) bool. Attributes:
// cutoff (float32), half (int64, 0 or 1). Results: i, j (K,) int32, S (K, 3) int32, count ()
// int32: the first min(count, K) pairs, then padding (i = j = N, S = 0). count > K: the list was
// cut (the caller grows K).
#include <cstdint>
#include <string>

#include "pair_outputs.hpp"
#include "raycut/engine.hpp"
#include "raycut/error.hpp"
#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

// One cell-list engine per thread, reused from call to call, and the list buffer it fills.
struct HostWork {
  raycut::Engine engine{"cell-list"};
  raycut::NeighbourListBuffer list;
};
HostWork& host_work() {
  thread_local HostWork work;
  return work;
}

template <class T>
void read_cell(const ffi::AnyBuffer& cell, raycut::Box& box) {
  const T* c = cell.typed_data<T>();
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) box.cell[r][k] = static_cast<double>(c[3 * r + k]);
}

ffi::Error neighbor_list(ffi::Buffer<ffi::F32> positions, ffi::AnyBuffer cell,
                         ffi::Buffer<ffi::PRED> pbc, float cutoff, std::int64_t half,
                         ffi::ResultBuffer<ffi::S32> i, ffi::ResultBuffer<ffi::S32> j,
                         ffi::ResultBuffer<ffi::S32> shifts, ffi::ResultBuffer<ffi::S32> count) {
  const auto dims = positions.dimensions();
  if (dims.size() != 2 || dims[1] != 3)
    return ffi::Error::InvalidArgument(
        "raycut.jax.neighbor_list: positions must have shape (N, 3)");
  if (cell.element_count() != 9 || pbc.element_count() != 3)
    return ffi::Error::InvalidArgument(
        "raycut.jax.neighbor_list: cell must be (3, 3) and pbc (3,)");
  raycut::Box box;
  if (cell.element_type() == ffi::F64) {
    read_cell<double>(cell, box);
  } else if (cell.element_type() == ffi::F32) {
    read_cell<float>(cell, box);
  } else {
    return ffi::Error::InvalidArgument("raycut.jax.neighbor_list: cell must be float32 or float64");
  }
  for (int r = 0; r < 3; ++r) box.pbc[r] = pbc.typed_data()[r];
  const auto n = static_cast<std::size_t>(dims[0]);
  HostWork& work = host_work();
  try {
    work.engine.build({positions.typed_data(), n, raycut::MemorySpace::host}, cutoff,
                      raycut::Systems::periodic(box));
    raycut::ListOptions options;
    options.half = half != 0;
    options.shifts = true;
    options.coo = true;
    work.engine.neighbours(work.list, options);
  } catch (const raycut::Error& e) {
    return ffi::Error::InvalidArgument(std::string("raycut.jax.neighbor_list: ") + e.what());
  }
  const auto pad = static_cast<std::int32_t>(n);
  const std::uint64_t found =
      raycut_py::write_pairs<std::int32_t>(work.list, i->element_count(), i->typed_data(),
                                           j->typed_data(), shifts->typed_data(), pad, pad);
  *count->typed_data() = static_cast<std::int32_t>(std::min<std::uint64_t>(found, INT32_MAX));
  return ffi::Error::Success();
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(RaycutNeighborList, neighbor_list,
                              ffi::Ffi::Bind()
                                  .Arg<ffi::Buffer<ffi::F32>>()   // positions (N, 3)
                                  .Arg<ffi::AnyBuffer>()          // cell (3, 3)
                                  .Arg<ffi::Buffer<ffi::PRED>>()  // pbc (3,)
                                  .Attr<float>("cutoff")
                                  .Attr<std::int64_t>("half")
                                  .Ret<ffi::Buffer<ffi::S32>>()  // i (K,)
                                  .Ret<ffi::Buffer<ffi::S32>>()  // j (K,)
                                  .Ret<ffi::Buffer<ffi::S32>>()  // S (K, 3)
                                  .Ret<ffi::Buffer<ffi::S32>>()  // count ()
);
