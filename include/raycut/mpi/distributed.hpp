// The distributed engine (docs/distributed.md): particles spread over the ranks of an MPI
// communicator by a Cartesian grid of spatial domains, each rank computing the targets it owns
// with any single-rank raycut method over its owned particles plus halo copies of the particles
// within cutoff + skin of its domain (periodic images across split axes included; a periodic
// axis with one domain is the local engine's own), owned rows only where the method takes query
// points. Indices are global throughout.
//
//   raycut::mpi::DistributedEngine engine(MPI_COMM_WORLD, {.method = "cell-list", .skin = 0.3f});
//   engine.build({xyz.data(), n, raycut::MemorySpace::host}, ids.data(), cutoff, box);
//   for (step...) {
//     raycut::Results r = engine.compute(raycut::Kernel::lj_forces);  // rows: engine.ids()
//     ... integrate engine.positions() (owned, in that order) into new_xyz ...
//     if (engine.update(new_xyz.data())) { ... the owned set changed: read ids() again ... }
//   }
//
// On GPUs (one rank per GPU): select_local_device(comm), options.transport =
// make_nccl_transport(comm), positions given in device memory; then each step is
// engine.run(kernel) (results on the device, rows engine.ids()), the integrator's device kernel
// over owned_positions(), and engine.update(device pointer). User pair functors:
// include/raycut/mpi/pairs.hpp.
//
// Host-only header; the only MPI type in it is MPI_Comm.
#pragma once

#include <mpi.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "raycut/box.hpp"
#include "raycut/engine.hpp"
#include "raycut/error.hpp"
#include "raycut/kernels.hpp"

namespace raycut::mpi {

namespace detail {  // the engine's parts (src/mpi)
class Exchange;
class Residence;
class LocalPasses;
}  // namespace detail

// Moves per-rank blocks of bytes between the ranks of a communicator: the payload of a
// migration or a halo exchange. Sizes are agreed beforehand over MPI (the engine's control
// plane), so a transport only moves data. A host transport moves everything; a device one
// (NCCL) moves what a device-resident engine (positions given in device memory) sends along its
// halo plan, GPU to GPU: the halo refreshes, the exchanges' halo records and halo fields; the
// migrants of an exchange (few) go through host-staged MPI.
class Transport {
 public:
  virtual ~Transport() = default;
  virtual std::string name() const = 0;
  // Where send and receive buffers must live.
  virtual MemorySpace space() const = 0;
  // Collective over the communicator: to rank r, send_counts[r] bytes from send +
  // send_offsets[r]; from rank r, recv_counts[r] bytes into recv + recv_offsets[r]. Every array
  // has one entry per rank; what rank a sends to b is what b expects from a.
  virtual void exchange(const std::byte* send, const std::uint64_t* send_counts,
                        const std::uint64_t* send_offsets, std::byte* recv,
                        const std::uint64_t* recv_counts, const std::uint64_t* recv_offsets) = 0;
};

// Host-staged MPI: nonblocking point-to-point sends and receives between the pairs of ranks
// with something to move (the neighbours of a domain), not a dense all-to-all. The
// communicator is duplicated, so its messages never mix with the caller's.
std::unique_ptr<Transport> make_host_transport(MPI_Comm comm);

// NCCL between the ranks' current CUDA devices, one rank per GPU (select_local_device): device
// buffers, ncclSend/ncclRecv pairs in one group on a stream of its own. Collective over `comm`.
// Error(unsupported) when raycut was built without NCCL (CMake finds nccl.h and libnccl with
// CUDA), Error(backend) when NCCL fails (two ranks on one GPU, say).
std::unique_ptr<Transport> make_nccl_transport(MPI_Comm comm);

// Makes the rank's node-local index (MPI_COMM_TYPE_SHARED) modulo the visible CUDA devices its
// current device and returns it; -1, changing nothing, without a CUDA device. Collective.
int select_local_device(MPI_Comm comm);

// The Cartesian grid of domains over the global region, in domain coordinates
// u_k = x . normal[k] (unit vectors, so u is in lengths and a halo of width h is h along every
// axis). A periodic axis k: normal[k] is the unit normal of the cell's faces across k,
// reciprocal_rows(box)[k] scaled to unit length, so u_k = f_k w_k (f the fractional coordinate,
// w_k = face_width(box, k)) and the region is [0, w_k); a shift by cell row m moves u_k by
// w_k if m == k, else not at all. An open axis k: e_k when every open e_k is orthogonal to every
// periodic row (orthorhombic boxes, slabs whose periodic rows lie in a coordinate plane), else
// the effective cell's unit completion row (box.hpp), orthogonal to the periodic rows; either
// way no periodic shift moves u_k. Its region is [0, L_k) with L_k = cell[k] . normal[k] when
// that is > 0, else the particles' extent along u_k at build(). Each axis is cut into dims[k]
// slabs at cuts[k] (dims[k] + 1 positions along u_k: equal slabs of the region, or moved to the
// particle-count quantiles by DistributedOptions::balance); on an open axis the first and last
// slabs extend to -inf and +inf, so a particle outside the region still has an owner. Domain
// (i, j, k) is rank (i dims[1] + j) dims[2] + k.
//
// A periodic axis with one domain is local (DistributedOptions::local_images, and a method that
// takes periodic boxes): the local engines are periodic along it themselves, so no halo crosses
// it; halos cross the other periodic axes (as images) and the split open ones.
struct Decomposition {
  std::array<int, 3> dims = {1, 1, 1};
  // Slab i of axis a is [cuts[a][i], cuts[a][i + 1]) in u_a. The inner cuts ascend, at least
  // cutoff + skin apart on an axis that halos cross; cuts[a].front() and .back() are the region's
  // ends (on a periodic axis 0 and the period), which bound no slab on an open axis.
  std::array<std::vector<double>, 3> cuts = {{{0, 0}, {0, 0}, {0, 0}}};
  std::array<bool, 3> periodic = {false, false, false};
  std::array<bool, 3> local = {false, false, false};  // periodic, one domain, the engines' own
  std::array<double, 3> length = {0, 0, 0};           // the period (face width) on periodic axes
  std::array<std::array<double, 3>, 3> normal = {{{1, 0, 0}, {0, 1, 0}, {0, 0, 1}}};
  std::array<std::array<double, 3>, 3> cell = {};  // the box's rows: images are x + S . cell
  // The normals are orthogonal (the domains are boxes): the halo test is Euclidean, else per
  // axis (docs/distributed.md).
  bool orthogonal = true;
  // The periodic rows lie along x, y, z with their normals: wrapped coordinate by coordinate.
  bool aligned = true;
  int domains() const { return dims[0] * dims[1] * dims[2]; }
  // Halos carry image shifts along `axis` (periodic, not local).
  bool images(int axis) const { return periodic[axis] && !local[axis]; }
  // Halos cross the faces across `axis` (split, or imaged by halos).
  bool halo_axis(int axis) const { return dims[axis] > 1 || images(axis); }
  // u_axis of a position.
  double coordinate(int axis, const float* xyz) const;
  // Slab index along `axis` of a domain coordinate (clamped to the grid): the inner cuts <= u.
  int slab(int axis, double u) const;
  // The owning domain (= rank) of a position.
  int owner(const float* xyz) const;
  std::array<int, 3> coords(int domain) const;
};

// Where the cuts go (docs/distributed.md): equal slabs of the region, or, per split axis, at the
// quantiles of the particle count along it (the processor grid stays Cartesian, as LAMMPS's
// `balance ... shift`), moved apart where a slab would be thinner than cutoff + skin.
enum class Balance { none, particles };

struct DistributedOptions {
  std::string method = "cell-list";  // any single-rank method of list_methods(), or "auto"
  // Halos reach cutoff + skin; halos are refreshed in place (positions only, no migration)
  // while no particle has moved more than skin / 2 since the last exchange. 0: every update()
  // migrates and rebuilds the halos.
  float skin = 0;
  // Domains per axis; 0 entries are chosen by MPI_Dims_create. The product must be the
  // communicator's size.
  std::array<int, 3> dims = {0, 0, 0};
  // Payload transport of what goes along the halo plan (refreshes, new halo records, halo
  // fields); null: make_host_transport(comm). A device transport (make_nccl_transport) serves a
  // device-resident engine; host-resident ones use host-staged MPI whatever is given here.
  std::shared_ptr<Transport> transport;
  // Owned rows only: one engine over the owned particles (pairs among them) and one with the
  // owned particles near a face as query points over the halos (pairs with halos), each owned
  // row visited through both and finished once. false, or a method that does not declare query
  // points (grid-paper, OptiX; raycut::method_capabilities), or a method that works on the GPU:
  // one engine over owned + halos, halo rows discarded (on a GPU the second build costs more
  // than the rows it saves). docs/distributed.md measures both.
  bool owned_rows_only = true;
  // A periodic axis with one domain: true, the local engines are periodic along it (no halo
  // crosses it, and it may be thinner than cutoff + skin); false, its images are sent as halos
  // (the all-axes scheme, which a method without periodic boxes, grid-paper or OptiX, gets
  // anyway). docs/distributed.md measures both.
  bool local_images = true;
  // Balance::particles: the cuts at build() and, when rebalance_every > 0, again at every
  // rebalance_every-th exchange after it (before its migration), from the particles then.
  Balance balance = Balance::none;
  int rebalance_every = 0;
};

// A neighbour list of the owned targets with global indices: the in-range sources of row t
// (global index targets[t]) are indices[offsets[t] .. offsets[t+1]).
struct DistributedList {
  std::vector<std::uint64_t> targets;  // one per row, owned order (DistributedEngine::ids())
  std::vector<std::uint64_t> offsets;  // rows + 1
  std::vector<std::uint64_t> indices;  // global source indices
  std::vector<float> distances;        // when asked
  std::vector<float> vectors;          // when asked: r = x_j - x_i + S . cell, 3 per entry
  // When asked: S per entry (3 int32), relative to the positions() of each particle's owner
  // (a particle is wrapped into the cell, fractional coordinates in [0, 1) on the periodic
  // axes, at every exchange).
  std::vector<std::int32_t> shifts;
};

// The inputs of sph_force for the owned particles: host arrays in ids() order, velocity (3 per
// particle), density and pressure. DistributedEngine::compute sends their halo copies.
struct SphFields {
  const float* velocity = nullptr;
  const float* density = nullptr;
  const float* pressure = nullptr;
};

// What the last passes cost; counters accumulate from build().
struct DistributedStats {
  std::uint64_t owned = 0, halos = 0;  // on this rank now
  std::uint64_t boundary = 0;          // owned rows that meet halos (owned rows only: queries)
  std::uint64_t exchanges = 0;         // full exchanges: migration + new halo sets
  std::uint64_t refreshes = 0;         // halo refreshes in place (skin)
  std::uint64_t migrated_out = 0;      // particles sent to other ranks by the last exchange
  std::uint64_t balances = 0;          // exchanges that moved the cuts (Balance::particles)
  std::uint64_t bytes_sent = 0;        // payload bytes sent to other ranks, last exchange/refresh
  double update_ms = 0;    // update()'s own pass, last call: copy, checks, skin test, agreement
  double exchange_ms = 0;  // wall time of the last exchange or refresh
  double build_ms = 0;     // the local engine's build/update, last pass
};

class DistributedEngine {
 public:
  // Collective over `comm` (kept, not duplicated: the caller keeps it alive). Throws, on every
  // rank, Error(invalid_argument) for bad dims or options or options that differ between ranks
  // (method, skin, dims, owned_rows_only, local_images, balance, rebalance_every), and the
  // error of a method that some rank does not know.
  explicit DistributedEngine(MPI_Comm comm, DistributedOptions options = {});
  ~DistributedEngine();
  DistributedEngine(const DistributedEngine&) = delete;
  DistributedEngine& operator=(const DistributedEngine&) = delete;

  // Collective. Each rank gives any subset of the particles (all on rank 0 and none elsewhere
  // is fine): positions, their global indices (host, distinct over all ranks), and `width`
  // floats per particle that travel with it on migration (velocities, say; carried() reads them
  // back). Then migrates every particle to its domain and builds the halos and the local engine.
  // Positions in device memory make the engine device-resident (the method must work on the
  // device, Engine::space(), else Error(unsupported)): carried floats and update()'s arrays are
  // then device memory too, the owned positions, halos and the local engine stay on the GPU
  // between exchanges, and run() leaves results there. Every rank must give the same space.
  // `box`: any box validate() accepts (open, orthorhombic or triclinic, periodic on any axes;
  // Decomposition says how domains follow it). Every domain must be at least cutoff + skin wide
  // (face width / dims) along each axis that halos cross (Decomposition::halo_axis: split in
  // more than one domain, or periodic and not local), else Error(invalid_argument) saying which;
  // with Balance::particles too (the region must hold dims equal slabs; the balanced cuts are
  // then kept that far apart).
  // An error found on one rank (a non-finite coordinate) is thrown on every rank.
  void build(PositionsView positions, const std::uint64_t* ids, float cutoff, const Box& box = {},
             const float* carried = nullptr, std::size_t width = 0);

  // Collective. New positions of the owned particles in owned order (3 floats each, ids()
  // order), and optionally their carried floats, in space() memory. Refreshes the halos in place
  // when the skin allows, else exchanges (migration, new halos). Returns true after an
  // exchange: the owned set and order may have changed (ids(), owned_positions(),
  // owned_carried() say how).
  bool update(const float* positions, const float* carried = nullptr);
  // Collective: an exchange now, whatever the skin.
  void exchange();

  // The kernel for every owned target; rows in ids() order. sph_force reads its neighbours'
  // fields: Error(unsupported) here, use the overload below.
  Results compute(Kernel kernel, const KernelOptions& options = {});
  // The same, results left where the method keeps them (a device-resident engine: on the GPU,
  // what an integrator there reads) and valid until the next call on this engine: rows
  // 0 .. owned() - 1 in ids() order (rows past them, if any, are not the owned targets').
  ResultsView run(Kernel kernel, const KernelOptions& options = {});
  // Collective for sph_force: the owned particles' fields, their halo copies sent by
  // halo_fields() (one exchange for all three), then sph_force over owned + halos, rows in ids()
  // order. options.sph is replaced by the local arrays. Error(invalid_argument) on every rank
  // when a rank with owned particles gives a null field; Error(unsupported) for a method that
  // works in device memory (the fields are host arrays in this slice). Other kernels ignore
  // `owned` (no exchange: compute(kernel, options)).
  Results compute(Kernel kernel, const KernelOptions& options, const SphFields& owned);
  // The same, results left where the method keeps them (run() above), with the fields in
  // space() memory: a device-resident engine sends their halo copies on the GPU (halo refreshes'
  // transport) and runs sph_force there. Other kernels ignore `owned`.
  ResultsView run(Kernel kernel, const KernelOptions& options, const SphFields& owned);
  // Collective: `width` floats per owned particle (host, ids() order) extended to the local
  // order of the engines: the owned values as given, then one copy per halo in halo_ids() order
  // (a periodic image gets its particle's values unchanged). Sent along the halo routes of the
  // last exchange or refresh: the same neighbours and record order as the positions. `width`
  // must be the same on every rank (else Error(invalid_argument) on every rank).
  std::vector<float> halo_fields(const float* owned, std::size_t width);
  // The same with device arrays, for a device-resident engine (else Error(unsupported) on every
  // rank): `owned` width floats per owned particle in, `local` width (owned() + halos()) floats
  // out, the halo copies gathered and sent on the GPU (the refreshes' transport).
  void halo_fields(const float* owned, std::size_t width, float* local);
  // The owned targets' neighbour lists with global indices. `half`: each pair (i, j, S) once
  // over all ranks, in the row of the smaller global index (i == j: S lexicographically
  // positive), as the single-rank half list orients local indices.
  DistributedList neighbours(const ListOptions& options = {});

  int rank() const { return rank_; }
  int size() const { return size_; }
  float cutoff() const { return cutoff_; }
  std::size_t owned() const { return ids_.size(); }
  std::size_t halos() const { return halo_count_; }
  // Where the owned positions and carried floats live: the space of build()'s positions.
  MemorySpace space() const;
  // The owned particles: global indices, positions (wrapped into the cell at the last exchange;
  // as given since), carried floats (width() per particle). positions() and carried() are host
  // copies; a device-resident engine downloads them at the first call after an exchange:
  // positions as of that exchange, carried floats as of that call (owned_positions() and
  // owned_carried() are current, in space() memory).
  const std::vector<std::uint64_t>& ids() const { return ids_; }
  const std::vector<float>& positions() const;
  const std::vector<float>& carried() const;
  PositionsView owned_positions() const;
  const float* owned_carried() const;
  std::size_t width() const { return width_; }
  // The halo copies: global indices and image shifts (3 per halo; 0 along local axes). A
  // device-resident engine downloads them at the first call after an exchange.
  const std::vector<std::uint64_t>& halo_ids() const;
  const std::vector<std::int32_t>& halo_shifts() const;
  // A device-resident engine's global indices in device memory (all null for a host-resident
  // one), current until the next exchange: the owned particles' (ids() order), the halos' and
  // their shifts (halo_ids() order, 3 per halo). For functors on the GPU (mpi/pairs.cuh).
  struct DeviceIds {
    const std::uint64_t* ids = nullptr;
    const std::uint64_t* halo_ids = nullptr;
    const std::int32_t* halo_shifts = nullptr;
  };
  DeviceIds device_ids() const;
  std::uint64_t global_size() const { return global_size_; }
  const Decomposition& decomposition() const { return decomposition_; }
  const DistributedStats& stats() const { return stats_; }
  // Whether the local passes compute the owned rows only (DistributedOptions::owned_rows_only
  // and a host method that declares query points and periodic boxes), or every row of owned +
  // halos.
  bool owned_rows_only() const;
  // The local engines (raycut::mpi::for_each_pair runs a functor through them): over owned +
  // halos, or with owned rows only over the owned particles, plus the boundary rows (owned
  // indices, ascending) as queries over the halos (null when it has nothing to do).
  const Engine& local_engine() const;
  const Engine* halo_engine() const;
  const std::vector<std::uint32_t>& boundary() const;

 private:
  void check_built(const char* call) const;
  void agree(const std::string& local_error, ErrorCode code);
  void setup();  // the constructor's local part, no collectives (its errors are agreed)
  void build_halos();
  void refresh_halos();
  void build_local_engine(bool same_sources);
  void check_field_width(const char* call, const float* owned, std::size_t width);
  void check_sph_fields(const SphFields& owned, bool device);

  MPI_Comm comm_;
  int rank_ = 0, size_ = 1;
  DistributedOptions options_;
  // The parts: the ranks' side (transports, the halo plan, migration); where the particles live
  // (host or device, chosen at build() from the positions' memory); the local engines and every
  // job on them (the scheme chosen at construction from the method's capabilities).
  std::unique_ptr<detail::Exchange> exchange_;
  std::unique_ptr<detail::Residence> residence_;
  std::unique_ptr<detail::LocalPasses> passes_;
  Decomposition decomposition_;
  // The local engines' box: the cell, periodic on the local axes only (the others cross by halos).
  Box local_box_;
  float cutoff_ = 0;
  double halo_width_ = 0;
  bool built_ = false;
  std::uint64_t global_size_ = 0;
  std::size_t width_ = 0;
  std::vector<std::uint64_t> ids_;
  std::size_t halo_count_ = 0;
  DistributedStats stats_;
};

}  // namespace raycut::mpi
