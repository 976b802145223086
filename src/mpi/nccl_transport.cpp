// The NCCL transport: device buffers moved GPU to GPU by ncclSend/ncclRecv pairs in one group
// (NVLink or PCIe peer copies within a host, the network between hosts), one rank per GPU. Its
// NCCL communicator is made over the caller's MPI communicator (the unique id broadcast by
// rank 0). Built only with CUDA and NCCL.
#include <cuda_runtime.h>
#include <nccl.h>

#include <string>

#include "mpi/mpi_check.hpp"
#include "raycut/detail/cuda/check.cuh"
#include "raycut/mpi/distributed.hpp"

namespace raycut::mpi {
namespace {

void check_nccl(ncclResult_t rc, const char* call) {
  if (rc == ncclSuccess) return;
  throw Error(ErrorCode::backend, std::string(call) + " failed: " + ncclGetErrorString(rc));
}

class NcclTransport final : public Transport {
 public:
  explicit NcclTransport(MPI_Comm comm) {
    check(MPI_Comm_rank(comm, &rank_), "MPI_Comm_rank");
    check(MPI_Comm_size(comm, &size_), "MPI_Comm_size");
    ncclUniqueId id;
    if (rank_ == 0) check_nccl(ncclGetUniqueId(&id), "ncclGetUniqueId");
    check(MPI_Bcast(&id, sizeof id, MPI_BYTE, 0, comm), "MPI_Bcast");
    check_nccl(ncclCommInitRank(&comm_, size_, id, rank_), "ncclCommInitRank");
    // A blocking stream: it waits for the legacy default stream's work (the engines' gathers)
    // and that stream waits for it, so no event is needed either way.
    RAYCUT_CUDA_CHECK(cudaStreamCreate(&stream_));
  }
  ~NcclTransport() override {
    cudaStreamDestroy(stream_);
    ncclCommDestroy(comm_);
  }
  std::string name() const override { return "nccl"; }
  MemorySpace space() const override { return MemorySpace::device; }

  void exchange(const std::byte* send, const std::uint64_t* send_counts,
                const std::uint64_t* send_offsets, std::byte* recv,
                const std::uint64_t* recv_counts, const std::uint64_t* recv_offsets) override {
    // Every pair of ranks with something to move, self included (NCCL copies a rank's send to
    // itself within the group); sizes were agreed over MPI, so the calls match.
    check_nccl(ncclGroupStart(), "ncclGroupStart");
    for (int r = 0; r < size_; ++r) {
      if (send_counts[r] > 0)
        check_nccl(ncclSend(send + send_offsets[r], send_counts[r], ncclUint8, r, comm_, stream_),
                   "ncclSend");
      if (recv_counts[r] > 0)
        check_nccl(ncclRecv(recv + recv_offsets[r], recv_counts[r], ncclUint8, r, comm_, stream_),
                   "ncclRecv");
    }
    check_nccl(ncclGroupEnd(), "ncclGroupEnd");
    RAYCUT_CUDA_CHECK(cudaStreamSynchronize(stream_));
  }

 private:
  ncclComm_t comm_ = nullptr;
  cudaStream_t stream_ = nullptr;
  int rank_ = 0, size_ = 1;
};

}  // namespace

std::unique_ptr<Transport> make_nccl_transport(MPI_Comm comm) {
  return std::make_unique<NcclTransport>(comm);
}

}  // namespace raycut::mpi
