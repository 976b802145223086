// The exchange part of the distributed engine: what crosses between ranks and how. Agreement on
// errors (every rank throws the first failing rank's error), the counts of each exchange over
// the communicator (the control plane), payloads through the transports (the data plane), the
// halo plan of the last exchange, the migration of particles to their owners, and the host's
// halo planning. Where the particles live (host or device) is the residence's (residence.hpp).
#pragma once

#include <mpi.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <memory>
#include <numeric>
#include <string>
#include <vector>

#include "mpi/device_residence.hpp"
#include "mpi/domains.hpp"
#include "raycut/error.hpp"
#include "raycut/mpi/distributed.hpp"

namespace raycut::mpi::detail {

class Residence;

// Owned particles per rank: the halo plan's and the migration's indices are 32-bit.
inline constexpr std::uint64_t max_owned = 0xffffffffull;

// Wire records: values appended to / read from a byte cursor.
template <class T>
void put(std::byte*& at, const T* values, std::size_t n) {
  std::memcpy(at, values, n * sizeof(T));
  at += n * sizeof(T);
}
template <class T>
void take(const std::byte*& at, T* values, std::size_t n) {
  std::memcpy(values, at, n * sizeof(T));
  at += n * sizeof(T);
}

// Per rank: counts[r] records of `scale` bytes as byte offsets and byte counts.
std::vector<std::uint64_t> offsets_of(const std::vector<std::uint64_t>& counts,
                                      std::uint64_t scale);
std::vector<std::uint64_t> scaled(const std::vector<std::uint64_t>& counts, std::uint64_t scale);

// Every rank throws when any rank found an error (local_error not empty): the lowest failing
// rank's message and code, so that no rank is left waiting in a collective the others abandoned.
// Collective over comm.
void agree(MPI_Comm comm, const std::string& local_error, ErrorCode code);
// The error of rank `first`, thrown on every rank. Collective over comm.
[[noreturn]] void throw_error_of(MPI_Comm comm, int first, const std::string& local_error,
                                 ErrorCode code);

// Where halo records go: per destination rank, the owned particle and the image shift, in the
// order they were sent (a refresh resends positions in the same order). A device-resident engine
// keeps index and shift on the GPU (DeviceResidence::plan_halos), the counts here.
struct HaloPlan {
  std::vector<std::uint64_t> send_counts, recv_counts;  // halos per rank
  std::vector<std::uint32_t> index;                     // owned index per record, by rank
  std::vector<std::int32_t> shift;                      // 3 per record
  std::uint64_t sent() const {
    return std::accumulate(send_counts.begin(), send_counts.end(), std::uint64_t{0});
  }
  std::uint64_t received() const {
    return std::accumulate(recv_counts.begin(), recv_counts.end(), std::uint64_t{0});
  }
};

// The particles that leave at a migration (found by the residence, on the host or the GPU).
using Leaving = DeviceResidence::Leaving;

// The ranks' side of the distributed engine: communicator, transports and the halo plan.
class Exchange {
 public:
  // Collective over comm (the host transport duplicates it). `transport`: the payload transport
  // of what goes along the halo plan (DistributedOptions::transport); null: the host one.
  Exchange(MPI_Comm comm, const std::shared_ptr<Transport>& transport);

  MPI_Comm comm() const { return comm_; }
  int rank() const { return rank_; }
  int size() const { return size_; }
  void agree(const std::string& local_error, ErrorCode code) const {
    detail::agree(comm_, local_error, code);
  }
  // What every rank receives from every rank, given what this rank sends to each. Collective.
  std::vector<std::uint64_t> counts(const std::vector<std::uint64_t>& send) const;
  // Records of `record` bytes, send_counts[r] of them to rank r (grouped by rank in order),
  // recv_counts[r] from rank r, through host-staged MPI. Collective over the ranks with
  // something to move.
  void on_host(const void* send, const std::vector<std::uint64_t>& send_counts, void* recv,
               const std::vector<std::uint64_t>& recv_counts, std::size_t record) const;
  // The same along the halo plan: the plan's records out, the halos' in.
  void along_plan_on_host(const void* send, void* recv, std::size_t record) const {
    on_host(send, plan_.send_counts, recv, plan_.recv_counts, record);
  }
  // The payload transport (the option's, or the host one) and the host one.
  Transport& payload() const { return *transport_; }
  Transport& host() const { return *host_transport_; }

  HaloPlan& plan() { return plan_; }
  const HaloPlan& plan() const { return plan_; }
  // Payload bytes of `record`-byte halo records sent to other ranks along the plan.
  std::uint64_t plan_bytes(std::size_t record) const {
    return (plan_.sent() - plan_.send_counts[static_cast<std::size_t>(rank_)]) * record;
  }

  // Every owned particle outside this rank's domain to its owner, with its global index and
  // carried floats; the staying keep their order, the arrivals follow in the order of their
  // ranks (the residence finds the owners and keeps the positions; ids are the host's). Returns
  // the number of particles sent. Collective; Error(out_of_memory) on every rank when a rank
  // would own more than max_owned.
  std::uint64_t migrate(Residence& residence, std::vector<std::uint64_t>& ids, std::size_t width,
                        DistributedStats& stats);

 private:
  MPI_Comm comm_;
  int rank_ = 0, size_ = 1;
  std::shared_ptr<Transport> transport_, host_transport_;
  HaloPlan plan_;
};

// migrate()'s owners on the host: per rank the particles it owns, and the leaving ones grouped
// by owner in index order, with their positions and carried floats (the GPU's:
// DeviceResidence::find_owners, the same owners in the same order).
void leaving_on_host(const Domains& domains, int rank, int size, const std::vector<float>& xyz,
                     const std::vector<float>& carried, std::size_t width, Leaving& leaving);

// Rows `gone` (ascending) removed from v (`width` values a row), the others kept in order.
template <class T>
void remove_rows(std::vector<T>& v, std::size_t width, const std::vector<std::uint32_t>& gone) {
  if (gone.empty() || width == 0) return;
  const std::size_t rows = v.size() / width;
  std::size_t to = width * gone[0];
  for (std::size_t k = 0; k < gone.size(); ++k) {
    const std::size_t from = gone[k] + 1, end = k + 1 < gone.size() ? gone[k + 1] : rows;
    std::copy(v.begin() + width * from, v.begin() + width * end, v.begin() + to);
    to += width * (end - from);
  }
  v.resize(to);
}

// The halo plan on the host (the GPU's: DeviceResidence::plan_halos): for_each_halo over the
// owned positions `xyz`, every record grouped by destination rank in particle order; sets
// plan.send_counts, index and shift.
void plan_halos_on_host(const Domains& domains, int rank, int size, double reach,
                        const std::vector<float>& xyz, HaloPlan& plan);

}  // namespace raycut::mpi::detail
