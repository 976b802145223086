// A caller's pair functor over the owned targets of a device-resident DistributedEngine (positions
// given in device memory), fused in its local engine's GPU traversal: the distributed form of
// raycut::cuda::for_each_pair (include/raycut/cuda/pairs.cuh says the functor's shape; compile
// with nvcc). What the functor sees is what include/raycut/mpi/pairs.hpp says for host methods:
// i an owned row (ids() order, finish(i) once per owned row), j a local source index (owned
// below owned(), then owned() + k for halo k), S the pair's global image shift. Per-source data
// comes from the device form of halo_fields(); global indices from device_ids().
//
//   std::vector<float> ... ;  DeviceArray q_local(...);                  // owned + halos
//   engine.halo_fields(q_owned_device, 1, q_local_device);
//   raycut::mpi::cuda::for_each_pair(engine, Coulomb{q_local_device, energy_device});
//
// Queued on the local engine's stream (the legacy default stream), like the single-engine call.
#pragma once

#include <cuda_runtime.h>

#include "raycut/cuda/pairs.cuh"
#include "raycut/mpi/pairs.hpp"

namespace raycut::mpi::cuda {

// Runs f for every owned target of the built engine (not collective). A host method runs
// raycut::mpi::for_each_pair; a GPU method needs a device-resident engine (else
// Error(unsupported): its halo shifts are on the host).
template <class F>
void for_each_pair(const DistributedEngine& engine, const F& f, cudaStream_t stream = nullptr) {
  static_assert(raycut::detail::check_functor<F>(),
                "raycut::mpi::cuda::for_each_pair: see the messages above");
  if (engine.local_engine().space() == MemorySpace::host) {
    raycut::mpi::for_each_pair(engine, f);
    return;
  }
  if (engine.space() != MemorySpace::device)
    throw Error(ErrorCode::unsupported,
                "raycut::mpi::cuda::for_each_pair: method '" + engine.local_engine().method() +
                    "' works on the GPU, but the engine was built from host positions; build it "
                    "from device positions (a device-resident engine)");
  // A device-resident engine runs all rows (one local engine over owned + halos).
  using Pass = detail::LocalPass<F, F>;  // f copied to the device
  const auto owned = static_cast<std::uint32_t>(engine.owned());
  const raycut::detail::RowMap rows{
      raycut::detail::RowKind::all_rows, owned, nullptr, nullptr, nullptr,
      engine.device_ids().halo_shifts};
  raycut::cuda::for_each_pair(engine.local_engine(), Pass{f, rows}, stream);
}

}  // namespace raycut::mpi::cuda
