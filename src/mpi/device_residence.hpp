// The device side of a device-resident DistributedEngine (positions given in device memory):
// what the local engine is built over and what a step touches, kept on the GPU so that a step
// with a skin is the plain engine's build + pass plus a displacement test and the halo refresh.
// Exchanges are planned on the GPU too, with the host's arithmetic (domains.hpp): the owners,
// the migration's order, the halo plan. The halo records (ids, images, shifts) are gathered and
// received here, so a device transport moves them GPU to GPU; the few migrants come to the host
// and cross there (docs/distributed.md, "The device-resident path"). Defined in
// device_residence.cu, only in builds with CUDA; host-only interface. Every call queues on the
// legacy default stream, the local engines' (DistributedEngine never sets a stream).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "mpi/domains.hpp"

namespace raycut::mpi::detail {

class DeviceResidence {
 public:
  virtual ~DeviceResidence() = default;

  // build(): copies of the owned positions and carried floats given in device memory (width
  // floats per particle), and the same to the host (build() checks them there); the global ids
  // (host) uploaded.
  virtual void adopt(const float* xyz, const float* carried, const std::uint64_t* ids,
                     std::size_t owned, std::size_t width, std::vector<float>& host_xyz,
                     std::vector<float>& host_carried) = 0;
  // The owned positions (now) and carried floats to the host; the carried floats alone.
  virtual void download(std::vector<float>& xyz, std::vector<float>& carried) const = 0;
  virtual void download_carried(std::vector<float>& carried) const = 0;
  // The owned positions at the last exchange (the skin's reference) to the host.
  virtual void download_reference(std::vector<float>& xyz) const = 0;

  // ---- an exchange, in this order ----
  // The decomposition the calls below use (its cuts copied to the device).
  virtual void set_domains(const Domains& domains) = 0;
  // The owned positions wrapped into the cell (Domains::wrap), in place.
  virtual void wrap() = 0;
  // The owners of the owned particles (Domains::owner). Per rank the particles it owns
  // (counts[rank]: those that stay), and those that leave, grouped by owner in index order
  // (the host's migration order): their indices, positions and carried floats, on the host.
  struct Leaving {
    std::vector<std::uint64_t> counts;
    std::vector<std::uint32_t> index;
    std::vector<float> xyz, carried;
  };
  virtual void find_owners(int rank, int ranks, Leaving& leaving) = 0;
  // After find_owners: the staying particles compacted in their order, then the arrivals (host
  // arrays, 3 and width floats and one id each) after them.
  virtual void keep_staying(const std::vector<float>& xyz, const std::vector<float>& carried,
                            const std::vector<std::uint64_t>& ids) = 0;
  // The halo plan of the owned particles (for_each_halo), kept on the device: per record the
  // owned index and image shift, grouped by rank in the host's order; per rank the records it
  // gets (host). The records to send, in that order, device arrays: gather() their positions,
  // gather_ids() their global ids, plan_shifts() their shifts (3 int32 each).
  virtual void plan_halos(int rank, int ranks, double reach,
                          std::vector<std::uint64_t>& counts) = 0;
  virtual const std::uint64_t* gather_ids() = 0;
  virtual const std::int32_t* plan_shifts() const = 0;
  // Room for `count` received halos, device arrays: their positions (after the owned ones in
  // local()), global ids and shifts. The owned positions become the skin's reference.
  struct HaloSlots {
    float* xyz;
    std::uint64_t* ids;
    std::int32_t* shifts;
  };
  virtual HaloSlots receive_halos(std::size_t count) = 0;
  // The received halos' ids and shifts to the host.
  virtual void download_halos(std::vector<std::uint64_t>& ids,
                              std::vector<std::int32_t>& shifts) const = 0;

  // ---- a step ----
  // update(): the new owned positions (device, 3 per owned particle) and carried floats
  // (device, or null: kept), in one pass that also finds the first non-finite coordinate and
  // whether a particle is more than `distance` from its place at the last exchange. With a
  // non-finite coordinate nothing is taken (the engine keeps its positions).
  struct Taken {
    std::size_t first_bad;  // index of the first owned particle with a non-finite coordinate,
                            // or owned() when none
    bool moved;             // some particle moved more than `distance`
  };
  virtual Taken take(const float* xyz, const float* carried, float distance) = 0;
  // The plan's halo records at the owned particles' current positions (3 floats each,
  // Domains::image), in a device buffer.
  virtual const float* gather() = 0;

  // ---- fields of the owned particles (sph_force's) ----
  // The plan's records of `width` floats per owned particle (device, owned order), in a device
  // buffer: the halos' copies to send.
  virtual const float* gather_fields(const float* owned, std::size_t width) = 0;
  // `count` floats of device memory, kept until the next call.
  virtual float* scratch(std::size_t count) = 0;
  // Bytes between any two of host and device memory (the direction from the pointers).
  virtual void copy(void* to, const void* from, std::size_t bytes) const = 0;
  // Host memory for staging `bytes` through a host transport, kept until the next call with
  // the same `which` (0 or 1): pinned (copies at the link's speed) where the host can pin it,
  // else pageable.
  virtual std::byte* staging(int which, std::size_t bytes) = 0;

  // The owned particles' global ids, the halos' ids and shifts (device).
  virtual const std::uint64_t* ids() const = 0;
  virtual const std::uint64_t* halo_ids() const = 0;
  virtual const std::int32_t* halo_shifts() const = 0;
  virtual std::size_t owned() const = 0;
  // Owned positions then halos: 3 (owned + halos) floats.
  virtual float* local() = 0;
  virtual const float* carried() const = 0;
};

// Only in builds with CUDA (device_residence.cu).
std::unique_ptr<DeviceResidence> make_device_residence();

}  // namespace raycut::mpi::detail
