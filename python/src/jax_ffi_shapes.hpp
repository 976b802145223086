// The shape checks the custom calls of pyraycut.jax share, on the CPU (jax_ffi.cpp) and on CUDA
// (jax_ffi_cuda.cu): what the inputs and results must look like, from the shapes alone.
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <utility>

#include "xla/ffi/api/ffi.h"

namespace raycut_jax {

namespace ffi = xla::ffi;

// A batch of equal systems (jax.vmap, vmap_method="broadcast_all"): positions (..., N, 3), cell
// (..., 3, 3), pbc (..., 3), count (...) and i with K slots per system. Sets the systems B (the
// product of the leading axes) and the particles per system N.
inline ffi::Error batched_shapes(const ffi::AnyBuffer::Dimensions& positions,
                                 std::size_t cell_entries, std::size_t pbc_entries,
                                 std::size_t count_entries, std::size_t i_entries,
                                 std::size_t& systems, std::size_t& n) {
  if (positions.size() < 2 || positions[positions.size() - 1] != 3)
    return ffi::Error::InvalidArgument(
        "raycut.jax.neighbor_list: positions must have shape (..., N, 3)");
  n = static_cast<std::size_t>(positions[positions.size() - 2]);
  systems = 1;
  for (std::size_t a = 0; a + 2 < positions.size(); ++a)
    systems *= static_cast<std::size_t>(positions[a]);
  if (cell_entries != 9 * systems || pbc_entries != 3 * systems || count_entries != systems ||
      (systems > 0 && i_entries % systems != 0))
    return ffi::Error::InvalidArgument(
        "raycut.jax.neighbor_list: cell must be (..., 3, 3) and pbc (..., 3), with the "
        "positions' leading axes");
  return ffi::Error::Success();
}

// A ragged batch: positions (N, 3), batch (N,), cell (B, 3, 3), pbc (B, 3). Sets N and B.
inline ffi::Error ragged_shapes(const ffi::AnyBuffer::Dimensions& positions,
                                std::size_t batch_entries, std::size_t cell_entries,
                                std::size_t pbc_entries, std::size_t& n, std::size_t& systems) {
  if (positions.size() != 2 || positions[1] != 3)
    return ffi::Error::InvalidArgument(
        "raycut.jax.neighbor_list: positions must have shape (N, 3) with batch");
  n = static_cast<std::size_t>(positions[0]);
  systems = cell_entries / 9;
  if (batch_entries != n || cell_entries != 9 * systems || pbc_entries != 3 * systems)
    return ffi::Error::InvalidArgument(
        "raycut.jax.neighbor_list: batch must be (N,), cell (B, 3, 3) and pbc (B, 3), got batch "
        "of " +
        std::to_string(batch_entries) + " entries for N = " + std::to_string(n) + ", " +
        std::to_string(cell_entries) + " cell entries and " + std::to_string(pbc_entries) +
        " pbc entries");
  return ffi::Error::Success();
}

// The targets' signatures after what a platform adds in front (CUDA: its stream and scratch
// allocator; the CPU: nothing): the same arguments, attributes and results everywhere.
// Both end with the attributes cutoff and half, and the results i, j (K,), S (K, 3) and count
// (with vmap's leading axes in front of each).
template <class Binding>
auto with_attributes_and_results(Binding binding) {
  return std::move(binding)
      .template Attr<float>("cutoff")
      .template Attr<std::int64_t>("half")
      .template Ret<ffi::Buffer<ffi::S32>>()
      .template Ret<ffi::Buffer<ffi::S32>>()
      .template Ret<ffi::Buffer<ffi::S32>>()
      .template Ret<ffi::Buffer<ffi::S32>>();
}

// RaycutNeighborList: positions (..., N, 3), cell (..., 3, 3), pbc (..., 3).
template <class Binding>
auto neighbor_list_signature(Binding binding) {
  return with_attributes_and_results(std::move(binding)
                                         .template Arg<ffi::Buffer<ffi::F32>>()
                                         .template Arg<ffi::AnyBuffer>()
                                         .template Arg<ffi::Buffer<ffi::PRED>>());
}

// RaycutRaggedNeighborList: positions (N, 3), batch (N,), cell (B, 3, 3), pbc (B, 3).
template <class Binding>
auto ragged_neighbor_list_signature(Binding binding) {
  return with_attributes_and_results(std::move(binding)
                                         .template Arg<ffi::Buffer<ffi::F32>>()
                                         .template Arg<ffi::Buffer<ffi::S32>>()
                                         .template Arg<ffi::AnyBuffer>()
                                         .template Arg<ffi::Buffer<ffi::PRED>>());
}

}  // namespace raycut_jax
