// raycut's neighbour list as an XLA FFI custom call on the CPU (pyraycut.jax,
// python/pyraycut/jax.py): static-capacity outputs, so that it runs inside jax.jit. Built as its
// own shared library, pyraycut/_jax_ffi.so, against the FFI headers jaxlib ships
// (jax.ffi.include_dir()); the Python side registers the handler symbol with
// jax.ffi.register_ffi_target.
//
// Inputs: positions (N, 3) float32; cell (3, 3) float32 or float64; pbc (3,) bool; or the same
// with leading batch axes (jax.vmap). Attributes: cutoff (float32), half (int64, 0 or 1).
// Results: i, j (K,) int32, S (K, 3) int32, count () int32 (per system under vmap): the first
// min(count, K) pairs, then padding (i = j = N, S = 0). count > K: the list was cut (the caller
// grows K).
//
// RaycutRaggedNeighborList: a ragged batch, positions (N, 3) with batch (N,) int32 (the sorted
// system index of each particle), cell (B, 3, 3) and pbc (B, 3); the same results over all
// systems at once, with global indices (padding i = j = N).
#include <algorithm>
#include <cstdint>
#include <string>
#include <vector>

#include "jax_ffi_shapes.hpp"
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
void read_cells(const ffi::AnyBuffer& cell, std::vector<raycut::Box>& boxes) {
  const T* c = cell.typed_data<T>();
  for (std::size_t b = 0; b < boxes.size(); ++b)
    for (int r = 0; r < 3; ++r)
      for (int k = 0; k < 3; ++k) boxes[b].cell[r][k] = static_cast<double>(c[9 * b + 3 * r + k]);
}

// Splits the batch's list (sorted by i, global indices) into each system's K slots: local
// indices, the first K pairs of each system, then padding (i = j = N, S = 0); counts[b] is the
// number of pairs of system b (over K: cut).
void write_systems(const raycut::NeighbourListBuffer& list, std::size_t systems, std::size_t n,
                   std::size_t k, std::int32_t* i, std::int32_t* j, std::int32_t* shifts,
                   std::int32_t* counts) {
  std::vector<std::uint64_t> found(systems, 0);
  const std::int64_t* rows = list.rows();
  const std::int64_t* columns = list.columns();
  const std::int32_t* s = list.shifts();
  for (std::uint64_t p = 0; p < list.pairs(); ++p) {
    const auto b = static_cast<std::size_t>(rows[p]) / n;
    const std::uint64_t slot = found[b]++;
    if (slot >= k) continue;
    const std::size_t at = b * k + slot;
    i[at] = static_cast<std::int32_t>(rows[p] - static_cast<std::int64_t>(b * n));
    j[at] = static_cast<std::int32_t>(columns[p] - static_cast<std::int64_t>(b * n));
    for (int a = 0; a < 3; ++a) shifts[3 * at + a] = s[3 * p + a];
  }
  for (std::size_t b = 0; b < systems; ++b) {
    for (std::size_t slot = std::min<std::uint64_t>(found[b], k); slot < k; ++slot) {
      i[b * k + slot] = j[b * k + slot] = static_cast<std::int32_t>(n);
      for (int a = 0; a < 3; ++a) shifts[3 * (b * k + slot) + a] = 0;
    }
    counts[b] = static_cast<std::int32_t>(std::min<std::uint64_t>(found[b], INT32_MAX));
  }
}

// Reads B cells (float32 or float64) and pbc flags into one box per system.
ffi::Error read_boxes(const ffi::AnyBuffer& cell, const ffi::Buffer<ffi::PRED>& pbc,
                      std::vector<raycut::Box>& boxes) {
  if (cell.element_type() == ffi::F64) {
    read_cells<double>(cell, boxes);
  } else if (cell.element_type() == ffi::F32) {
    read_cells<float>(cell, boxes);
  } else {
    return ffi::Error::InvalidArgument("raycut.jax.neighbor_list: cell must be float32 or float64");
  }
  for (std::size_t b = 0; b < boxes.size(); ++b)
    for (int r = 0; r < 3; ++r) boxes[b].pbc[r] = pbc.typed_data()[3 * b + r];
  return ffi::Error::Success();
}

// One engine build over all systems and the list (sorted by i, global indices) in work.list.
ffi::Error search(const float* positions, std::size_t n, float cutoff, std::int64_t half,
                  const raycut::Systems& systems, HostWork& work) {
  try {
    work.engine.build({positions, n, raycut::MemorySpace::host}, cutoff, systems);
    raycut::ListOptions options;
    options.half = half != 0;
    options.shifts = true;
    options.coo = true;
    work.engine.neighbours(work.list, options);
  } catch (const raycut::Error& e) {
    return ffi::Error::InvalidArgument(std::string("raycut.jax.neighbor_list: ") + e.what());
  }
  return ffi::Error::Success();
}

// Leading axes (jax.vmap with vmap_method="broadcast_all") are a batch of B systems of N points
// each, searched in one engine build (raycut::Systems offsets and one box per system), not a
// loop.
ffi::Error neighbor_list(ffi::Buffer<ffi::F32> positions, ffi::AnyBuffer cell,
                         ffi::Buffer<ffi::PRED> pbc, float cutoff, std::int64_t half,
                         ffi::ResultBuffer<ffi::S32> i, ffi::ResultBuffer<ffi::S32> j,
                         ffi::ResultBuffer<ffi::S32> shifts, ffi::ResultBuffer<ffi::S32> count) {
  std::size_t systems = 0, n = 0;
  if (ffi::Error error = raycut_jax::batched_shapes(positions.dimensions(), cell.element_count(),
                                                    pbc.element_count(), count->element_count(),
                                                    i->element_count(), systems, n);
      error.failure())
    return error;
  std::vector<raycut::Box> boxes(systems);
  if (ffi::Error error = read_boxes(cell, pbc, boxes); error.failure()) return error;
  raycut::Systems batch;
  if (systems == 1) {
    batch.box = boxes[0];
  } else {
    batch.boxes = std::move(boxes);
    batch.offsets.resize(systems + 1);
    for (std::size_t b = 0; b <= systems; ++b) batch.offsets[b] = b * n;
  }
  HostWork& work = host_work();
  if (ffi::Error error = search(positions.typed_data(), systems * n, cutoff, half, batch, work);
      error.failure())
    return error;
  if (systems > 0)
    write_systems(work.list, systems, n, i->element_count() / systems, i->typed_data(),
                  j->typed_data(), shifts->typed_data(), count->typed_data());
  return ffi::Error::Success();
}

// A ragged batch: particle p belongs to system batch[p] (sorted, each < B, B = the cells'
// count), turned into the library's offsets, and the systems searched in one build.
ffi::Error ragged_neighbor_list(ffi::Buffer<ffi::F32> positions, ffi::Buffer<ffi::S32> batch,
                                ffi::AnyBuffer cell, ffi::Buffer<ffi::PRED> pbc, float cutoff,
                                std::int64_t half, ffi::ResultBuffer<ffi::S32> i,
                                ffi::ResultBuffer<ffi::S32> j, ffi::ResultBuffer<ffi::S32> shifts,
                                ffi::ResultBuffer<ffi::S32> count) {
  std::size_t n = 0, systems = 0;
  if (ffi::Error error =
          raycut_jax::ragged_shapes(positions.dimensions(), batch.element_count(),
                                    cell.element_count(), pbc.element_count(), n, systems);
      error.failure())
    return error;
  raycut::Systems ragged;
  ragged.offsets.assign(systems + 1, 0);
  const std::int32_t* system_of = batch.typed_data();
  for (std::size_t p = 0; p < n; ++p) {
    const std::int32_t s = system_of[p];
    if (s < 0 || static_cast<std::size_t>(s) >= systems)
      return ffi::Error::InvalidArgument(
          "raycut.jax.neighbor_list: batch[" + std::to_string(p) + "] = " + std::to_string(s) +
          " is not a system index in [0, " + std::to_string(systems) + ") (B from the cell)");
    if (p > 0 && s < system_of[p - 1])
      return ffi::Error::InvalidArgument(
          "raycut.jax.neighbor_list: batch must be sorted (non-decreasing), but batch[" +
          std::to_string(p) + "] = " + std::to_string(s) + " < batch[" + std::to_string(p - 1) +
          "] = " + std::to_string(system_of[p - 1]));
    ++ragged.offsets[static_cast<std::size_t>(s) + 1];  // sizes, summed into offsets below
  }
  for (std::size_t s = 0; s < systems; ++s) ragged.offsets[s + 1] += ragged.offsets[s];
  ragged.boxes.resize(systems);
  if (ffi::Error error = read_boxes(cell, pbc, ragged.boxes); error.failure()) return error;
  const std::size_t k = i->element_count();
  if (n == 0) {  // no particles (B may be 0): no search, all padding
    std::fill_n(i->typed_data(), k, 0);
    std::fill_n(j->typed_data(), k, 0);
    std::fill_n(shifts->typed_data(), 3 * k, 0);
    *count->typed_data() = 0;
    return ffi::Error::Success();
  }
  HostWork& work = host_work();
  if (ffi::Error error = search(positions.typed_data(), n, cutoff, half, ragged, work);
      error.failure())
    return error;
  // One system of N points in write_systems' terms: global indices, padding i = j = N.
  write_systems(work.list, 1, n, k, i->typed_data(), j->typed_data(), shifts->typed_data(),
                count->typed_data());
  return ffi::Error::Success();
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(RaycutNeighborList, neighbor_list,
                              raycut_jax::neighbor_list_signature(ffi::Ffi::Bind()));

XLA_FFI_DEFINE_HANDLER_SYMBOL(RaycutRaggedNeighborList, ragged_neighbor_list,
                              raycut_jax::ragged_neighbor_list_signature(ffi::Ffi::Bind()));

// The XLA FFI API version of the headers this library was built with, major * 1000 + minor.
// pyraycut.jax refuses to register the handlers with a jaxlib whose API is older: XLA refuses
// them only when it creates its CPU client, which then fails for every JAX computation.
extern "C" int RaycutXlaFfiApiVersion() {
  return XLA_FFI_API_MAJOR * 1000 + XLA_FFI_API_MINOR;
}
