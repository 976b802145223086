// Host-staged MPI transport: point-to-point messages between the ranks that have something to
// move, on a duplicate of the caller's communicator.
#include <algorithm>
#include <cstring>
#include <string>
#include <vector>

#include "mpi/mpi_check.hpp"
#include "raycut/mpi/distributed.hpp"
#if defined(RAYCUT_HAVE_CUDA)
#include <cuda_runtime.h>

#include "raycut/detail/cuda/check.cuh"
#endif

namespace raycut::mpi {
namespace {

// MPI counts are int: larger blocks go as several messages of at most this many bytes.
constexpr std::uint64_t chunk_bytes = std::uint64_t{1} << 30;

class HostTransport final : public Transport {
 public:
  explicit HostTransport(MPI_Comm comm) {
    check(MPI_Comm_dup(comm, &comm_), "MPI_Comm_dup");
    MPI_Comm_rank(comm_, &rank_);
    MPI_Comm_size(comm_, &size_);
  }
  ~HostTransport() override {
    int finalized = 0;
    MPI_Finalized(&finalized);
    if (!finalized) MPI_Comm_free(&comm_);
  }
  std::string name() const override { return "mpi-host"; }
  MemorySpace space() const override { return MemorySpace::host; }

  void exchange(const std::byte* send, const std::uint64_t* send_counts,
                const std::uint64_t* send_offsets, std::byte* recv,
                const std::uint64_t* recv_counts, const std::uint64_t* recv_offsets) override {
    std::vector<MPI_Request> requests;
    // Each other rank's block in chunks of at most chunk_bytes (MPI counts are int), one request
    // a chunk: post(at, n, rank, tag, request) posts one.
    const auto each_chunk = [&](const std::uint64_t* counts, auto&& post) {
      for (int r = 0; r < size_; ++r) {
        if (r == rank_) continue;
        for (std::uint64_t at = 0, tag = 0; at < counts[r]; at += chunk_bytes, ++tag) {
          requests.emplace_back();
          post(at, static_cast<int>(std::min(chunk_bytes, counts[r] - at)), r,
               static_cast<int>(tag), &requests.back());
        }
      }
    };
    // Receives first, so that every send finds its receive posted.
    each_chunk(recv_counts, [&](std::uint64_t at, int n, int r, int tag, MPI_Request* request) {
      check(MPI_Irecv(recv + recv_offsets[r] + at, n, MPI_BYTE, r, tag, comm_, request),
            "MPI_Irecv");
    });
    each_chunk(send_counts, [&](std::uint64_t at, int n, int r, int tag, MPI_Request* request) {
      check(MPI_Isend(send + send_offsets[r] + at, n, MPI_BYTE, r, tag, comm_, request),
            "MPI_Isend");
    });
    if (send_counts[rank_] != recv_counts[rank_])
      throw Error(ErrorCode::internal, "host transport: self block sizes differ");
    if (send_counts[rank_] > 0)
      std::memcpy(recv + recv_offsets[rank_], send + send_offsets[rank_], send_counts[rank_]);
    check(MPI_Waitall(static_cast<int>(requests.size()), requests.data(), MPI_STATUSES_IGNORE),
          "MPI_Waitall");
  }

 private:
  MPI_Comm comm_ = MPI_COMM_NULL;
  int rank_ = 0, size_ = 1;
};

}  // namespace

std::unique_ptr<Transport> make_host_transport(MPI_Comm comm) {
  return std::make_unique<HostTransport>(comm);
}

#if !defined(RAYCUT_HAVE_NCCL)
std::unique_ptr<Transport> make_nccl_transport(MPI_Comm) {
  throw Error(ErrorCode::unsupported,
              "make_nccl_transport: raycut was built without NCCL (CMake finds it with CUDA, "
              "nccl.h and libnccl); use make_host_transport");
}
#endif

int select_local_device(MPI_Comm comm) {
  MPI_Comm node = MPI_COMM_NULL;
  check(MPI_Comm_split_type(comm, MPI_COMM_TYPE_SHARED, 0, MPI_INFO_NULL, &node),
        "MPI_Comm_split_type");
  int local = 0;
  MPI_Comm_rank(node, &local);
  MPI_Comm_free(&node);
#if defined(RAYCUT_HAVE_CUDA)
  int devices = 0;
  if (cudaGetDeviceCount(&devices) != cudaSuccess || devices == 0) {
    (void)cudaGetLastError();  // no device: not an error here
    return -1;
  }
  RAYCUT_CUDA_CHECK(cudaSetDevice(local % devices));
  return local % devices;
#else
  (void)local;
  return -1;
#endif
}

}  // namespace raycut::mpi
