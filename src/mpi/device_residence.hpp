// The device side of a device-resident DistributedEngine (positions given in device memory):
// what the local engine is built over and what a step touches, kept on the GPU so that a step
// with a skin is the plain engine's build + pass plus a displacement test and the halo refresh.
// Exchanges are planned on the GPU too, with the host's arithmetic (domains.hpp): the owners,
// the migration's order, the halo plan. Only what crosses ranks (migrants, halo records) and the
// plan's indices come to the host, where DistributedEngine sends them as a host-resident engine
// does (docs/distributed.md, "The device-resident path"). Defined in device_residence.cu, only in
// builds with CUDA; host-only interface. Every call queues on the legacy default stream, the
// local engines' (DistributedEngine never sets a stream).
#pragma once

#include <array>
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
  // floats per particle), and the same to the host (build() checks them there).
  virtual void adopt(const float* xyz, const float* carried, std::size_t owned, std::size_t width,
                     std::vector<float>& host_xyz, std::vector<float>& host_carried) = 0;
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
  // arrays, 3 and width floats each) after them.
  virtual void keep_staying(const std::vector<float>& xyz, const std::vector<float>& carried) = 0;
  // The halo plan of the owned particles (for_each_halo): per rank the records it gets, and per
  // record the owned index and image shift (3 int32), grouped by rank in the host's order, on
  // the host. gather() makes the records' positions.
  virtual void plan_halos(int rank, int ranks, double reach, std::vector<std::uint64_t>& counts,
                          std::vector<std::uint32_t>& index, std::vector<std::int32_t>& shift) = 0;
  // The received halos (3 floats each, host) after the owned positions; the owned positions
  // become the skin's reference.
  virtual void set_halos(const std::vector<float>& xyz) = 0;

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
  // Received halo positions from the host (3 floats per halo) into the local array.
  virtual void upload_halos(const float* xyz) = 0;
  // The gathered records to the host (3 floats each).
  virtual void download_gathered(std::vector<float>& xyz) const = 0;

  // ---- fields of the owned particles (sph_force's) ----
  // The plan's records of `width` floats per owned particle (device, owned order), in a device
  // buffer: the halos' copies to send.
  virtual const float* gather_fields(const float* owned, std::size_t width) = 0;
  // Three device arrays of `count`, 3 count and `count` floats (velocity, density, pressure of
  // owned + halos), kept until the next call.
  virtual std::array<float*, 3> sph_fields(std::size_t count) = 0;
  // Bytes between any two of host and device memory (the direction from the pointers).
  virtual void copy(void* to, const void* from, std::size_t bytes) const = 0;

  virtual std::size_t owned() const = 0;
  // Owned positions then halos: 3 (owned + halos) floats.
  virtual float* local() = 0;
  virtual const float* carried() const = 0;
};

// Only in builds with CUDA (device_residence.cu).
std::unique_ptr<DeviceResidence> make_device_residence();

}  // namespace raycut::mpi::detail
