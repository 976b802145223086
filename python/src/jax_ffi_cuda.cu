// pyraycut.jax's custom calls on CUDA: the same targets, inputs and results as the CPU handlers
// (jax_ffi.cpp), registered with platform "CUDA" by python/pyraycut/jax.py when the library was
// built with CUDA. They run the library's stream-ordered small-system pass
// (raycut::list_pairs_small_systems, raycut/device_pairs.hpp) on XLA's stream, with temporaries
// from XLA's scratch allocator: no host synchronisation, and no device data read on the host.
//
// - Positions are float32, as on the CPU. A float32 cell is passed as it is; with a float64 cell
//   the positions are widened to float64 on the device (the pass takes one scalar type for both,
//   and widening loses nothing, where narrowing the cell would).
// - The pass writes int64 i, j and count into scratch and the int32 shifts straight into XLA's
//   S; one kernel then narrows i, j and the counts into XLA's int32 results.
// - Bad device data (a non-finite position, an unsorted batch, a degenerate cell, a system index
//   outside [0, B)) cannot be an error of the call without reading the device: the count is the
//   library's negative code instead (-1 non-finite position, -2 unsorted batch, -3 invalid cell,
//   -4 system index out of range), and the pairs are all padding.
// - Larger systems (raycut::prefer_small_systems false) take the same path, with cells from 2,048
//   particles a system (PairOptions::search automatic): slower than the library's grids, which
//   synchronise with the host and so have no place here yet.
#include <cuda_runtime.h>

#include <algorithm>
#include <climits>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <optional>
#include <string>

#include "jax_ffi_shapes.hpp"
#include "raycut/context.hpp"
#include "raycut/device_pairs.hpp"
#include "raycut/error.hpp"
#include "xla/ffi/api/ffi.h"

namespace ffi = xla::ffi;

namespace {

constexpr unsigned block_threads = 256;

unsigned blocks_for(std::size_t work) {
  return static_cast<unsigned>(
      std::clamp<std::size_t>((work + block_threads - 1) / block_threads, 1, 4096));
}

// XLA's scratch memory as the pass's memory resource. XLA hands it back to its allocator when
// the handler returns, while the work queued here may still run: safe because whatever XLA puts
// in that memory next runs on this same stream, after it. Nothing to do on deallocate.
class ScratchResource final : public raycut::MemoryResource {
 public:
  explicit ScratchResource(ffi::ScratchAllocator& scratch) : scratch_(scratch) {}
  void* allocate(std::size_t bytes, void*) override {
    // 16 bytes: the largest alignment XLA's FFI accepts (it refuses more, and the reason does
    // not reach the handler); its device allocator aligns blocks far more than that anyway.
    const std::optional<void*> p = scratch_.Allocate(std::max<std::size_t>(bytes, 1), 16);
    if (!p || !*p)
      throw raycut::Error(raycut::ErrorCode::out_of_memory,
                          "XLA's scratch allocator gave no " + std::to_string(bytes) +
                              " bytes (16-byte aligned): device memory is short");
    return *p;
  }
  void deallocate(void*, std::size_t, void*) noexcept override {}
  template <class T>
  T* array(std::size_t count) {
    return static_cast<T*>(allocate(count * sizeof(T), nullptr));
  }

 private:
  ffi::ScratchAllocator& scratch_;
};

// XLA's device for the handler's scope: XLA calls it on a thread whose current device may be
// another GPU than the one that owns its stream (jax.pmap, several GPUs), and the pass, CUB and
// the launches here all use the current one.
class DeviceGuard {
 public:
  explicit DeviceGuard(std::int32_t device) {
    if (cudaGetDevice(&previous_) == cudaSuccess && previous_ != device &&
        cudaSetDevice(device) == cudaSuccess)
      return;
    previous_ = -1;  // already there, or unknown: nothing to restore
    (void)cudaGetLastError();
  }
  ~DeviceGuard() {
    if (previous_ >= 0) cudaSetDevice(previous_);
  }
  DeviceGuard(const DeviceGuard&) = delete;
  DeviceGuard& operator=(const DeviceGuard&) = delete;

 private:
  int previous_ = -1;
};

__global__ void widen(const float* in, double* out, std::size_t count) {
  for (std::size_t k = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x; k < count;
       k += std::size_t{gridDim.x} * blockDim.x)
    out[k] = in[k];
}

// The ragged batch as the pass's int64 system index. A value outside [0, systems) becomes -1,
// which the pass reports as a negative count (with one cell for all systems it would not look).
__global__ void system_index(const std::int32_t* in, std::int64_t* out, std::size_t n,
                             std::int64_t systems) {
  for (std::size_t k = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x; k < n;
       k += std::size_t{gridDim.x} * blockDim.x)
    out[k] = in[k] >= 0 && in[k] < systems ? in[k] : -1;
}

// The system of each of B x N particles (jax.vmap's batch): k / N.
__global__ void systems_of_rows(std::int64_t* out, std::size_t n, std::size_t count) {
  for (std::size_t k = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x; k < count;
       k += std::size_t{gridDim.x} * blockDim.x)
    out[k] = static_cast<std::int64_t>(k / n);
}

// XLA's int32 results from the pass's int64 ones: i, j (entries) and the counts (one per
// system). A count above INT32_MAX is clamped (it still says "cut"); negative codes pass through.
// `local`: a list per system of `local` particles (K = entries / systems slots each), whose
// global indices become local ones (padding stays `local`).
__global__ void narrow(const std::int64_t* i64, const std::int64_t* j64, const std::int64_t* c64,
                       std::int32_t* i, std::int32_t* j, std::int32_t* count, std::size_t entries,
                       std::size_t systems, std::size_t local = 0) {
  const std::size_t first = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
  const std::size_t stride = std::size_t{gridDim.x} * blockDim.x;
  const std::size_t k_slots = local && systems ? entries / systems : 0;
  for (std::size_t k = first; k < entries; k += stride) {
    std::int64_t offset = 0;
    if (local) {
      const std::size_t b = k / k_slots;
      const std::int64_t pairs = c64[b];
      const bool pair = pairs >= 0 && static_cast<std::int64_t>(k - b * k_slots) < pairs;
      offset = pair ? static_cast<std::int64_t>(b * local) : 0;
    }
    i[k] = static_cast<std::int32_t>(i64[k] - offset);
    j[k] = static_cast<std::int32_t>(j64[k] - offset);
  }
  for (std::size_t b = first; b < systems; b += stride)
    count[b] = static_cast<std::int32_t>(c64[b] < INT32_MAX ? c64[b] : INT32_MAX);
}

ffi::Error launched(const char* what) {
  const cudaError_t status = cudaGetLastError();
  if (status == cudaSuccess) return ffi::Error::Success();
  return ffi::Error::Internal(std::string("raycut.jax.neighbor_list: ") + what + ": " +
                              cudaGetErrorString(status));
}

ffi::Error failed(const raycut::Error& e) {
  const std::string message = std::string("raycut.jax.neighbor_list: ") + e.what();
  return e.code() == raycut::ErrorCode::invalid_argument ||
                 e.code() == raycut::ErrorCode::invalid_input
             ? ffi::Error::InvalidArgument(message)
             : ffi::Error::Internal(message);
}

// The positions and cells the pass reads: float32 both, or both float64 (positions widened into
// scratch) for a float64 cell.
struct Coordinates {
  const void* positions = nullptr;
  const void* cells = nullptr;
  raycut::Scalar scalar = raycut::Scalar::float32;
  std::size_t scalar_bytes = sizeof(float);
};

ffi::Error coordinates(cudaStream_t stream, const ffi::Buffer<ffi::F32>& positions,
                       const ffi::AnyBuffer& cell, ScratchResource& scratch, Coordinates& out) {
  out.cells = cell.untyped_data();
  if (cell.element_type() == ffi::F32) {
    out.positions = positions.typed_data();
    return ffi::Error::Success();
  }
  if (cell.element_type() != ffi::F64)
    return ffi::Error::InvalidArgument("raycut.jax.neighbor_list: cell must be float32 or float64");
  const std::size_t count = positions.element_count();
  auto* wide = scratch.array<double>(count);
  if (count > 0)
    widen<<<blocks_for(count), block_threads, 0, stream>>>(positions.typed_data(), wide, count);
  out.positions = wide;
  out.scalar = raycut::Scalar::float64;
  out.scalar_bytes = sizeof(double);
  return launched("widening the positions to float64");
}

ffi::Error check_indices(std::size_t n) {
  if (n >= static_cast<std::size_t>(INT32_MAX))
    return ffi::Error::InvalidArgument("raycut.jax.neighbor_list: N = " + std::to_string(n) +
                                       " particles do not fit the int32 indices (N < 2^31 - 1)");
  return ffi::Error::Success();
}

// The pass over `all` into int64 scratch (with `lists` > 0, a list of K slots per system, else
// one list of K), then XLA's int32 results narrowed from it (local indices with a list per
// system of `n` particles).
ffi::Error pass_and_narrow(cudaStream_t stream, ScratchResource& scratch,
                           const raycut::DeviceSystems& all, float cutoff, std::int64_t half,
                           std::size_t lists, std::size_t k, std::size_t n,
                           ffi::ResultBuffer<ffi::S32>& i, ffi::ResultBuffer<ffi::S32>& j,
                           ffi::ResultBuffer<ffi::S32>& shifts,
                           ffi::ResultBuffer<ffi::S32>& count) {
  const std::size_t counts = std::max<std::size_t>(lists, 1), entries = counts * k;
  raycut::StaticPairs out;
  out.i = scratch.array<std::int64_t>(entries);
  out.j = scratch.array<std::int64_t>(entries);
  out.shifts = shifts->typed_data();
  out.count = scratch.array<std::int64_t>(counts);
  out.capacity = k;
  out.pad_index = static_cast<std::int64_t>(n);
  out.systems = lists;
  raycut::PairOptions options;
  options.half = half != 0;
  raycut::list_pairs_small_systems(raycut::Context{stream, &scratch}, all, cutoff, options, out);
  narrow<<<blocks_for(std::max(entries, counts)), block_threads, 0, stream>>>(
      out.i, out.j, out.count, i->typed_data(), j->typed_data(), count->typed_data(), entries,
      counts, lists ? n : 0);
  return launched("writing the int32 results");
}

// B systems of N particles (jax.vmap): one pass over all of them with a list per system
// (StaticPairs::systems), each writing its own K slots and its own count, so that every count is
// exact even when other systems overflow their slots; then one kernel narrows all of them to
// local int32 indices.
ffi::Error neighbor_list(cudaStream_t stream, ffi::ScratchAllocator scratch_allocator,
                         std::int32_t device, ffi::Buffer<ffi::F32> positions, ffi::AnyBuffer cell,
                         ffi::Buffer<ffi::PRED> pbc, float cutoff, std::int64_t half,
                         ffi::ResultBuffer<ffi::S32> i, ffi::ResultBuffer<ffi::S32> j,
                         ffi::ResultBuffer<ffi::S32> shifts, ffi::ResultBuffer<ffi::S32> count) {
  std::size_t systems = 0, n = 0;
  if (ffi::Error error = raycut_jax::batched_shapes(positions.dimensions(), cell.element_count(),
                                                    pbc.element_count(), count->element_count(),
                                                    i->element_count(), systems, n);
      error.failure())
    return error;
  if (ffi::Error error = check_indices(n); error.failure()) return error;
  if (systems == 0) return ffi::Error::Success();
  const std::size_t k = i->element_count() / systems;
  const DeviceGuard on_device(device);
  ScratchResource scratch(scratch_allocator);
  try {
    Coordinates at;
    if (ffi::Error error = coordinates(stream, positions, cell, scratch, at); error.failure())
      return error;
    auto* batch = scratch.array<std::int64_t>(systems * n);
    if (systems * n > 0)
      systems_of_rows<<<blocks_for(systems * n), block_threads, 0, stream>>>(batch, n, systems * n);
    raycut::DeviceSystems all;
    all.positions = at.positions;
    all.scalar = at.scalar;
    all.size = systems * n;
    all.cells = at.cells;
    all.cell_count = systems;
    all.pbc = pbc.typed_data();
    all.pbc_count = systems;
    all.batch = batch;
    return pass_and_narrow(stream, scratch, all, cutoff, half, systems, k, n, i, j, shifts, count);
  } catch (const raycut::Error& e) {
    return failed(e);
  } catch (const std::exception& e) {  // nothing may cross into XLA as an exception
    return ffi::Error::Internal(std::string("raycut.jax.neighbor_list: ") + e.what());
  }
}

// A ragged batch: one pass over all systems (the batch widened to int64 on the device), global
// indices, padding i = j = N, one count.
ffi::Error ragged_neighbor_list(cudaStream_t stream, ffi::ScratchAllocator scratch_allocator,
                                std::int32_t device, ffi::Buffer<ffi::F32> positions,
                                ffi::Buffer<ffi::S32> batch, ffi::AnyBuffer cell,
                                ffi::Buffer<ffi::PRED> pbc, float cutoff, std::int64_t half,
                                ffi::ResultBuffer<ffi::S32> i, ffi::ResultBuffer<ffi::S32> j,
                                ffi::ResultBuffer<ffi::S32> shifts,
                                ffi::ResultBuffer<ffi::S32> count) {
  std::size_t n = 0, systems = 0;
  if (ffi::Error error =
          raycut_jax::ragged_shapes(positions.dimensions(), batch.element_count(),
                                    cell.element_count(), pbc.element_count(), n, systems);
      error.failure())
    return error;
  if (ffi::Error error = check_indices(n); error.failure()) return error;
  if (n > 0 && systems == 0)
    return ffi::Error::InvalidArgument(
        "raycut.jax.neighbor_list: a ragged batch of N = " + std::to_string(n) +
        " particles needs at least one system (cell (B, 3, 3) with B >= 1), got B = 0");
  const std::size_t k = i->element_count();
  const DeviceGuard on_device(device);
  ScratchResource scratch(scratch_allocator);
  try {
    Coordinates at;
    if (ffi::Error error = coordinates(stream, positions, cell, scratch, at); error.failure())
      return error;
    raycut::DeviceSystems all;
    all.positions = at.positions;
    all.scalar = at.scalar;
    all.size = n;
    if (n > 0) {  // no particles (B may be 0): no systems, the pass writes only padding
      auto* system_of = scratch.array<std::int64_t>(n);
      system_index<<<blocks_for(n), block_threads, 0, stream>>>(batch.typed_data(), system_of, n,
                                                                static_cast<std::int64_t>(systems));
      if (ffi::Error error = launched("widening the batch to int64"); error.failure()) return error;
      all.cells = at.cells;
      all.cell_count = systems;
      all.pbc = pbc.typed_data();
      all.pbc_count = systems;
      all.batch = system_of;
    }
    return pass_and_narrow(stream, scratch, all, cutoff, half, 0, k, n, i, j, shifts, count);
  } catch (const raycut::Error& e) {
    return failed(e);
  } catch (const std::exception& e) {  // nothing may cross into XLA as an exception
    return ffi::Error::Internal(std::string("raycut.jax.neighbor_list: ") + e.what());
  }
}

}  // namespace

XLA_FFI_DEFINE_HANDLER_SYMBOL(
    RaycutNeighborListCuda, neighbor_list,
    raycut_jax::neighbor_list_signature(ffi::Ffi::Bind()
                                            .Ctx<ffi::PlatformStream<cudaStream_t>>()
                                            .Ctx<ffi::ScratchAllocator>()
                                            .Ctx<ffi::DeviceOrdinal>()));

XLA_FFI_DEFINE_HANDLER_SYMBOL(
    RaycutRaggedNeighborListCuda, ragged_neighbor_list,
    raycut_jax::ragged_neighbor_list_signature(ffi::Ffi::Bind()
                                                   .Ctx<ffi::PlatformStream<cudaStream_t>>()
                                                   .Ctx<ffi::ScratchAllocator>()
                                                   .Ctx<ffi::DeviceOrdinal>()));
