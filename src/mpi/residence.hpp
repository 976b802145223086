// Where a distributed engine's particles live, chosen once at build() from the positions' memory
// space: host-resident (host arrays, planned and exchanged on the host) or device-resident (the
// owned positions, halos and local engine's inputs on the GPU between exchanges; exchanges
// planned there with the host's arithmetic, domains.hpp). The engine calls the same steps on
// either; each residence does them where its particles are (docs/distributed.md).
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <vector>

#include "mpi/domains.hpp"
#include "mpi/exchange.hpp"
#include "raycut/engine.hpp"
#include "raycut/mpi/distributed.hpp"

namespace raycut::mpi::detail {

class Residence {
 public:
  virtual ~Residence() = default;
  // Where the owned positions, carried floats and the local engine's positions live.
  virtual MemorySpace space() const = 0;

  // ---- build() ----
  // The owned particles as given (positions and carried floats in space() memory, `width`
  // floats each; ids on the host), copied. positions() and carried() then hold host copies,
  // which build() checks.
  virtual void adopt(const float* xyz, const float* carried, const std::uint64_t* ids,
                     std::size_t n, std::size_t width) = 0;

  // ---- what the engine reads back ----
  // Host copies: the owned positions (a device-resident engine's as of the last exchange) and
  // carried floats (as of this call), the halos' global ids and shifts.
  virtual const std::vector<float>& positions() const = 0;
  virtual const std::vector<float>& carried() const = 0;
  virtual const std::vector<std::uint64_t>& halo_ids() const = 0;
  virtual const std::vector<std::int32_t>& halo_shifts() const = 0;
  // In space() memory: the owned positions (current), carried floats, and the owned positions
  // then the halos' (what the local engines are built over), `count` of them.
  virtual PositionsView owned_positions(std::size_t owned) const = 0;
  virtual const float* owned_carried() const = 0;
  virtual PositionsView local_positions(std::size_t count) = 0;
  // Global ids in device memory (all null on the host).
  virtual DistributedEngine::DeviceIds device_ids() const = 0;

  // ---- update() ----
  // New owned positions (and carried floats, or null) in space() memory: the index of the first
  // with a non-finite coordinate (or the owned count) and whether one moved more than
  // `distance` from its place at the last exchange. A device-resident engine takes them here
  // (none with a non-finite coordinate), a host-resident one in accept(), once every rank agreed.
  struct Moves {
    std::size_t first_bad;
    bool moved;
  };
  virtual Moves check_moves(const float* xyz, const float* carried, double distance) = 0;
  virtual void accept(const float* xyz, const float* carried) = 0;

  // ---- an exchange, in this order ----
  // The decomposition the calls below use (valid until the next call).
  virtual void set_domains(const Domains& domains) = 0;
  // The owned positions wrapped into the cell (Domains::wrap).
  virtual void wrap() = 0;
  // The current owned positions on the host (after wrap(): what Balance::particles counts).
  virtual const std::vector<float>& current_positions() = 0;
  // The owners (Exchange::migrate): per rank the particles it owns, and those that leave.
  virtual void find_owners(int rank, int size, Leaving& leaving) = 0;
  // After find_owners: the staying particles (all but `gone`, ascending) compacted in their
  // order, then the arrivals (host arrays).
  virtual void keep_staying(const std::vector<std::uint32_t>& gone, const std::vector<float>& xyz,
                            const std::vector<float>& carried,
                            const std::vector<std::uint64_t>& ids) = 0;
  // A new halo plan (exchange.plan(), its counts agreed) and the halos along it:
  // [id][image xyz][shift] records; `ids` the owned particles' global ones. Returns the number
  // of halos. The owned positions become the skin's reference. Collective.
  virtual std::size_t build_halos(Exchange& exchange, const std::vector<std::uint64_t>& ids,
                                  double reach) = 0;
  // The same halos at their owners' current positions, along the plan. Collective.
  virtual void refresh_halos(Exchange& exchange) = 0;

  // ---- fields of the owned particles ----
  // `width` floats per owned particle extended to owned + halos: the owned values, then the
  // halos' copies along the plan (the same records as the positions). In space() memory; the
  // same from and to host memory. Collective over the ranks that send or receive halos.
  virtual void halo_fields(Exchange& exchange, const float* owned, std::size_t width,
                           float* local) = 0;
  virtual void halo_fields_on_host(Exchange& exchange, const float* owned, std::size_t width,
                                   float* local) = 0;
  // sph_force's velocity, density and pressure of owned + halos in space() memory, from the
  // owned particles' (space() memory), valid until the next call. Collective.
  virtual SphInputs sph_fields(Exchange& exchange, const SphFields& owned) = 0;
};

// The host-resident one; the device-resident one (builds with CUDA only: Error(internal)
// otherwise; the method must work on the device, which build() checks first).
std::unique_ptr<Residence> make_host_residence();
std::unique_ptr<Residence> make_device_resident();

}  // namespace raycut::mpi::detail
