// The exchange (exchange.hpp): agreement, counts, host-staged payloads, migration, host halo plans.
#include "mpi/exchange.hpp"

#include <algorithm>

#include <omp.h>

#include "mpi/mpi_check.hpp"
#include "mpi/residence.hpp"

namespace raycut::mpi::detail {

std::vector<std::uint64_t> offsets_of(const std::vector<std::uint64_t>& counts,
                                      std::uint64_t scale) {
  std::vector<std::uint64_t> offsets(counts.size());
  std::uint64_t at = 0;
  for (std::size_t r = 0; r < counts.size(); ++r) {
    offsets[r] = at;
    at += counts[r] * scale;
  }
  return offsets;
}

std::vector<std::uint64_t> scaled(const std::vector<std::uint64_t>& counts, std::uint64_t scale) {
  std::vector<std::uint64_t> out(counts);
  for (auto& c : out) c *= scale;
  return out;
}

void agree(MPI_Comm comm, const std::string& local_error, ErrorCode code) {
  int rank = 0, size = 1;
  check(MPI_Comm_rank(comm, &rank), "MPI_Comm_rank");
  check(MPI_Comm_size(comm, &size), "MPI_Comm_size");
  int failed = local_error.empty() ? size : rank;
  int first = size;
  check(MPI_Allreduce(&failed, &first, 1, MPI_INT, MPI_MIN, comm), "MPI_Allreduce");
  if (first != size) throw_error_of(comm, first, local_error, code);
}

void throw_error_of(MPI_Comm comm, int first, const std::string& local_error, ErrorCode code) {
  std::string message = local_error;
  int header[2] = {static_cast<int>(message.size()), static_cast<int>(code)};
  MPI_Bcast(header, 2, MPI_INT, first, comm);
  message.resize(static_cast<std::size_t>(header[0]));
  MPI_Bcast(message.data(), header[0], MPI_CHAR, first, comm);
  throw Error(static_cast<ErrorCode>(header[1]), "rank " + std::to_string(first) + ": " + message);
}

// A host transport given in the options serves everything; else a host one of its own for the
// migrants (and everything of a host-resident engine).
Exchange::Exchange(MPI_Comm comm, const std::shared_ptr<Transport>& transport) : comm_(comm) {
  check(MPI_Comm_rank(comm_, &rank_), "MPI_Comm_rank");
  check(MPI_Comm_size(comm_, &size_), "MPI_Comm_size");
  const bool host_given = transport && transport->space() == MemorySpace::host;
  host_transport_ = host_given ? transport : make_host_transport(comm_);
  transport_ = transport ? transport : host_transport_;
}

std::vector<std::uint64_t> Exchange::counts(const std::vector<std::uint64_t>& send) const {
  std::vector<std::uint64_t> recv(static_cast<std::size_t>(size_), 0);
  check(MPI_Alltoall(send.data(), 1, MPI_UINT64_T, recv.data(), 1, MPI_UINT64_T, comm_),
        "MPI_Alltoall");
  return recv;
}

void Exchange::on_host(const void* send, const std::vector<std::uint64_t>& send_counts, void* recv,
                       const std::vector<std::uint64_t>& recv_counts, std::size_t record) const {
  host_transport_->exchange(static_cast<const std::byte*>(send), scaled(send_counts, record).data(),
                            offsets_of(send_counts, record).data(), static_cast<std::byte*>(recv),
                            scaled(recv_counts, record).data(),
                            offsets_of(recv_counts, record).data());
}

// [id][xyz][carried] records, by owner, in index order; the records cross on the host.
std::uint64_t Exchange::migrate(Residence& residence, std::vector<std::uint64_t>& ids,
                                std::size_t width, DistributedStats& stats) {
  const std::size_t record = sizeof(std::uint64_t) + (3 + width) * sizeof(float);
  Leaving leaving;
  residence.find_owners(rank_, size_, leaving);
  std::vector<std::uint64_t> send_counts = leaving.counts;
  send_counts[static_cast<std::size_t>(rank_)] = 0;  // kept in place, not sent
  const std::vector<std::uint64_t> recv_counts = counts(send_counts);
  const std::uint64_t received =
      std::accumulate(recv_counts.begin(), recv_counts.end(), std::uint64_t{0});
  const std::uint64_t owning = leaving.counts[static_cast<std::size_t>(rank_)] + received;
  agree(owning > max_owned ? "distributed exchange: rank " + std::to_string(rank_) + " would own " +
                                 std::to_string(owning) +
                                 " particles, more than 2^32 - 1 (the exchange's indices are "
                                 "32-bit); use more ranks"
                           : std::string(),
        ErrorCode::out_of_memory);
  const std::size_t sent = leaving.index.size();
  std::vector<std::byte> send(sent * record), recv(received * record);
  std::byte* at = send.data();
  for (std::size_t j = 0; j < sent; ++j) {
    put(at, &ids[leaving.index[j]], 1);
    put(at, &leaving.xyz[3 * j], 3);
    put(at, leaving.carried.data() + width * j, width);
  }
  on_host(send.data(), send_counts, recv.data(), recv_counts, record);

  std::vector<std::uint32_t> gone = leaving.index;
  std::sort(gone.begin(), gone.end());
  remove_rows(ids, 1, gone);
  std::vector<float> xyz(3 * received), carried(width * received);  // the arrivals'
  std::vector<std::uint64_t> arrived(received);
  const std::byte* from = recv.data();
  for (std::uint64_t k = 0; k < received; ++k) {
    take(from, &arrived[k], 1);
    take(from, &xyz[3 * k], 3);
    take(from, carried.data() + width * k, width);
  }
  ids.insert(ids.end(), arrived.begin(), arrived.end());
  residence.keep_staying(gone, xyz, carried, arrived);
  stats.migrated_out = sent;
  stats.bytes_sent += sent * record;
  return sent;
}

void leaving_on_host(const Domains& domains, int rank, int size, const std::vector<float>& xyz,
                     const std::vector<float>& carried, std::size_t width, Leaving& leaving) {
  const std::size_t n = xyz.size() / 3;
  std::vector<int> dest(n);
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(n); ++i)
    dest[i] = domains.owner(&xyz[3 * i]);
  leaving.counts.assign(static_cast<std::size_t>(size), 0);
  for (int d : dest) ++leaving.counts[static_cast<std::size_t>(d)];
  std::vector<std::uint64_t> cursor(static_cast<std::size_t>(size), 0);
  std::uint64_t at = 0;
  for (int r = 0; r < size; ++r) {
    cursor[r] = at;
    if (r != rank) at += leaving.counts[r];
  }
  const std::size_t gone = n - leaving.counts[static_cast<std::size_t>(rank)];
  leaving.index.resize(gone);
  leaving.xyz.resize(3 * gone);
  leaving.carried.resize(width * gone);
  for (std::size_t i = 0; i < n; ++i) {
    if (dest[i] == rank) continue;
    const std::uint64_t j = cursor[static_cast<std::size_t>(dest[i])]++;
    leaving.index[j] = static_cast<std::uint32_t>(i);
    std::copy_n(&xyz[3 * i], 3, &leaving.xyz[3 * j]);
    std::copy_n(carried.begin() + width * i, width, leaving.carried.begin() + width * j);
  }
}

// In OpenMP threads: threads take contiguous blocks of particles in order (a static schedule),
// so appending their per-rank routes in thread order gives the serial order: the same plan
// whatever the thread count (and the GPU's, which sorts the serial records by rank).
void plan_halos_on_host(const Domains& domains, int rank, int size, double reach,
                        const std::vector<float>& xyz, HaloPlan& plan) {
  const std::size_t n = xyz.size() / 3;
  bool any_crossed = false;  // else nothing is sent (one rank, every periodic axis local)
  for (int a = 0; a < 3; ++a) any_crossed = any_crossed || domains.crossed[a];
  struct Routes {
    std::vector<std::vector<std::uint32_t>> index;
    std::vector<std::vector<std::int32_t>> shift;
  };
  std::vector<Routes> routes(static_cast<std::size_t>(omp_get_max_threads()));
  const Faces faces(domains, rank);
#pragma omp parallel if (any_crossed)
  {
    Routes& mine = routes[static_cast<std::size_t>(omp_get_thread_num())];
    mine.index.resize(static_cast<std::size_t>(size));
    mine.shift.resize(static_cast<std::size_t>(size));
#pragma omp for schedule(static)
    for (std::ptrdiff_t i = 0; i < (any_crossed ? static_cast<std::ptrdiff_t>(n) : 0); ++i)
      for_each_halo(domains, faces, rank, reach, &xyz[3 * i], [&](int q, const std::int32_t* s) {
        mine.index[q].push_back(static_cast<std::uint32_t>(i));
        mine.shift[q].insert(mine.shift[q].end(), s, s + 3);
      });
  }
  plan.send_counts.assign(static_cast<std::size_t>(size), 0);
  plan.index.clear();
  plan.shift.clear();
  for (int r = 0; r < size; ++r)
    for (Routes& mine : routes) {
      if (mine.index.empty()) continue;  // a thread the team did not have
      plan.send_counts[r] += mine.index[r].size();
      plan.index.insert(plan.index.end(), mine.index[r].begin(), mine.index[r].end());
      plan.shift.insert(plan.shift.end(), mine.shift[r].begin(), mine.shift[r].end());
    }
}

}  // namespace raycut::mpi::detail
