// The device side of a device-resident DistributedEngine (device_residence.hpp). Compiled with
// --fmad=false (CMakeLists.txt), so that domains.hpp's arithmetic rounds here as on the host.
#include <cuda_runtime.h>

#include <algorithm>
#include <cstddef>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <string>
#include <utility>
#include <vector>

#include "core/validation.hpp"
#include "cuda/device_buffer.cuh"
#include "cuda/runtime.hpp"
#include "mpi/device_residence.hpp"

namespace raycut::mpi::detail {
namespace {

namespace cuda = raycut::detail::cuda;

__device__ std::size_t first_index() {
  return blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
}
__device__ std::size_t stride() {
  return std::size_t{gridDim.x} * blockDim.x;
}

__global__ void gather_images(Domains d, const float* xyz, const std::uint32_t* index,
                              const std::int32_t* shift, std::size_t records, float* out) {
  for (std::size_t k = first_index(); k < records; k += stride())
    d.image(xyz + 3 * std::size_t{index[k]}, shift + 3 * k, out + 3 * k);
}

// update()'s pass over the owned particles: the new positions into `out` (the other half of a
// double buffer), the first non-finite coordinate (atomicMin over report[0], which starts at
// all ones) and whether one moved more than the skin's half (report[1] set to 0, from all ones).
__global__ void take_positions(const float* xyz, const float* reference, std::size_t n,
                               float limit_squared, float* out, unsigned long long* report) {
  for (std::size_t i = first_index(); i < n; i += stride()) {
    float d2 = 0;
    bool finite = true;
    for (int a = 0; a < 3; ++a) {
      const float x = xyz[3 * i + a];
      finite = finite && isfinite(x);
      const float d = x - reference[3 * i + a];
      d2 += d * d;
      out[3 * i + a] = x;
    }
    if (!finite) atomicMin(&report[0], static_cast<unsigned long long>(i));
    if (!(d2 <= limit_squared)) report[1] = 0;  // racing writes of the same value
  }
}

__global__ void wrap_positions(Domains d, float* xyz, std::size_t n) {
  for (std::size_t i = first_index(); i < n; i += stride()) d.wrap(xyz + 3 * i);
}

__global__ void find_owner(Domains d, const float* xyz, std::size_t n, std::uint32_t* owner,
                           std::uint32_t* index) {
  for (std::size_t i = first_index(); i < n; i += stride()) {
    owner[i] = static_cast<std::uint32_t>(d.owner(xyz + 3 * i));
    index[i] = static_cast<std::uint32_t>(i);
  }
}

// starts[r] = the first k with sorted[k] >= r, for r in [0, keys]: where each key's run begins.
__global__ void key_starts(const std::uint32_t* sorted, std::size_t n, int keys,
                           unsigned long long* starts) {
  for (std::size_t r = first_index(); r <= static_cast<std::size_t>(keys); r += stride()) {
    std::size_t low = 0, high = n;
    while (low < high) {
      const std::size_t mid = (low + high) / 2;
      if (sorted[mid] < r)
        low = mid + 1;
      else
        high = mid;
    }
    starts[r] = low;
  }
}

// to[k] = from[rows[k]], `width` values a row.
template <class T>
__global__ void gather_rows(const T* from, const std::uint32_t* rows, std::size_t count,
                            std::size_t width, T* to) {
  for (std::size_t e = first_index(); e < count * width; e += stride())
    to[e] = from[width * rows[e / width] + e % width];
}

__global__ void count_halos(Domains d, int rank, double reach, const float* xyz, std::size_t n,
                            unsigned long long* counts) {
  const Faces faces(d, rank);
  for (std::size_t i = first_index(); i < n; i += stride()) {
    unsigned long long c = 0;
    for_each_halo(d, faces, rank, reach, xyz + 3 * i, [&](int, const std::int32_t*) { ++c; });
    counts[i] = c;
  }
}

// Particle i's records at offsets[i] on, in for_each_halo's order.
__global__ void write_halos(Domains d, int rank, double reach, const float* xyz, std::size_t n,
                            const unsigned long long* offsets, std::uint32_t* dest,
                            std::uint32_t* index, std::int32_t* shift) {
  const Faces faces(d, rank);
  for (std::size_t i = first_index(); i < n; i += stride()) {
    std::size_t k = offsets[i];
    for_each_halo(d, faces, rank, reach, xyz + 3 * i, [&](int q, const std::int32_t* s) {
      dest[k] = static_cast<std::uint32_t>(q);
      index[k] = static_cast<std::uint32_t>(i);
      for (int c = 0; c < 3; ++c) shift[3 * k + c] = s[c];
      ++k;
    });
  }
}

__global__ void iota(std::uint32_t* out, std::size_t n) {
  for (std::size_t i = first_index(); i < n; i += stride()) out[i] = static_cast<std::uint32_t>(i);
}

// Record k of the sorted plan is record order[k] of the unsorted one.
__global__ void gather_records(const std::uint32_t* order, std::size_t n,
                               const std::uint32_t* index, const std::int32_t* shift,
                               std::uint32_t* index_out, std::int32_t* shift_out) {
  for (std::size_t k = first_index(); k < n; k += stride()) {
    const std::uint32_t from = order[k];
    index_out[k] = index[from];
    for (int c = 0; c < 3; ++c) shift_out[3 * k + c] = shift[3 * std::size_t{from} + c];
  }
}

unsigned blocks_for(std::size_t n) {
  return static_cast<unsigned>(std::clamp<std::size_t>((n + 255) / 256, 1, 4096));
}

int bits_for(int keys) {
  int bits = 1;
  while ((1 << bits) < keys) ++bits;
  return bits;
}

// `count` values between host and device memory, either way.
template <class T>
void copy_n(T* to, const T* from, std::size_t count) {
  cuda::copy(to, from, count * sizeof(T));
}
template <class T>
void download_to(std::vector<T>& to, const T* from, std::size_t count) {
  to.resize(count);
  copy_n(to.data(), from, count);
}

// Grow-only host memory, pinned when the host allows it (else pageable: a failed pin is no
// error, the copies are only slower).
class StagingBuffer {
 public:
  StagingBuffer() = default;
  StagingBuffer(const StagingBuffer&) = delete;
  StagingBuffer& operator=(const StagingBuffer&) = delete;
  ~StagingBuffer() { release(); }
  std::byte* at_least(std::size_t bytes) {
    if (bytes <= capacity_) return data_;
    release();
    void* p = nullptr;
    if (cudaHostAlloc(&p, bytes, cudaHostAllocPortable) == cudaSuccess) {
      pinned_ = static_cast<std::byte*>(p);
      data_ = pinned_;
    } else {
      (void)cudaGetLastError();  // clear the failed allocation's error
      pageable_.resize(bytes);
      data_ = pageable_.data();
    }
    capacity_ = bytes;
    return data_;
  }

 private:
  void release() {
    if (pinned_) cudaFreeHost(pinned_);
    pinned_ = data_ = nullptr;
    pageable_.clear();
    pageable_.shrink_to_fit();
    capacity_ = 0;
  }
  std::byte* pinned_ = nullptr;
  std::byte* data_ = nullptr;
  std::vector<std::byte> pageable_;
  std::size_t capacity_ = 0;
};

class CudaResidence final : public DeviceResidence {
 public:
  void adopt(const float* xyz, const float* carried, const std::uint64_t* ids, std::size_t owned,
             std::size_t width, std::vector<float>& host_xyz,
             std::vector<float>& host_carried) override {
    owned_ = owned;
    halos_ = records_ = 0;
    width_ = width;
    local_.resize(3 * owned);
    carried_.resize(width * owned);
    ids_.resize(owned);
    copy_n(local_.data(), xyz, 3 * owned);
    copy_n(carried_.data(), carried, width * owned);
    copy_n(ids_.data(), ids, owned);
    download(host_xyz, host_carried);
  }

  void download(std::vector<float>& xyz, std::vector<float>& carried) const override {
    download_to(xyz, local_.data(), 3 * owned_);
    download_carried(carried);
  }

  void download_carried(std::vector<float>& carried) const override {
    download_to(carried, carried_.data(), width_ * owned_);
  }

  void download_reference(std::vector<float>& xyz) const override {
    download_to(xyz, reference_.data(), 3 * owned_);
  }

  void set_domains(const Domains& domains) override {
    domains_ = domains;
    std::vector<double> cuts;
    for (int a = 0; a < 3; ++a)
      cuts.insert(cuts.end(), domains.cuts[a], domains.cuts[a] + domains.dims[a] + 1);
    cuts_.resize(cuts.size());
    copy_n(cuts_.data(), cuts.data(), cuts.size());
    for (int a = 0, at = 0; a < 3; at += domains.dims[a] + 1, ++a)
      domains_.cuts[a] = cuts_.data() + at;
  }

  void wrap() override {
    if (owned_ == 0) return;
    wrap_positions<<<blocks_for(owned_), 256>>>(domains_, local_.data(), owned_);
    RAYCUT_CUDA_CHECK_LAUNCH();
  }

  void find_owners(int rank, int ranks, Leaving& leaving) override {
    const std::size_t n = owned_;
    leaving.counts.assign(static_cast<std::size_t>(ranks), 0);
    leaving.counts[static_cast<std::size_t>(rank)] = n;
    leaving.index.clear();
    leaving.xyz.clear();
    leaving.carried.clear();
    sorted_ = false;
    if (ranks == 1 || n == 0) return;  // everything stays, in order
    owner_.resize(n);
    owner_sorted_.resize(n);
    order_in_.resize(n);
    order_.resize(n);
    find_owner<<<blocks_for(n), 256>>>(domains_, local_.data(), n, owner_.data(), order_in_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    sort_by_key(owner_, owner_sorted_, order_in_, order_, n, ranks);  // stable: index order
    runs(owner_sorted_.data(), n, ranks, leaving.counts);
    sorted_ = true;
    // The staying particles are the run of `rank`, the leaving ones the runs around it.
    staying_first_ = 0;
    for (int r = 0; r < rank; ++r) staying_first_ += leaving.counts[static_cast<std::size_t>(r)];
    const std::size_t staying = leaving.counts[static_cast<std::size_t>(rank)];
    staying_ = staying;
    const std::size_t gone = n - staying;
    if (gone == 0) {  // the order is the identity
      sorted_ = false;
      return;
    }
    leaving_.resize(gone);
    copy_n(leaving_.data(), order_.data(), staying_first_);
    copy_n(leaving_.data() + staying_first_, order_.data() + staying_first_ + staying,
           gone - staying_first_);
    download_to(leaving.index, leaving_.data(), gone);
    rows_.resize(std::max<std::size_t>(3, width_) * gone);
    gather(local_.data(), leaving_.data(), gone, 3, leaving.xyz);
    gather(carried_.data(), leaving_.data(), gone, width_, leaving.carried);
  }

  void keep_staying(const std::vector<float>& xyz, const std::vector<float>& carried,
                    const std::vector<std::uint64_t>& ids) override {
    if (!sorted_ && ids.empty()) return;  // nothing left, nothing came
    const std::size_t staying = sorted_ ? staying_ : owned_;
    const std::size_t arrived = ids.size(), n = staying + arrived;
    staged_.resize(3 * n);
    carried_staged_.resize(width_ * n);
    ids_staged_.resize(n);
    const std::uint32_t* kept = order_.data() + staying_first_;
    if (sorted_) {
      gather_rows_into(local_.data(), kept, staying, 3, staged_.data());
      gather_rows_into(carried_.data(), kept, staying, width_, carried_staged_.data());
      gather_rows_into(ids_.data(), kept, staying, 1, ids_staged_.data());
    } else {
      copy_n(staged_.data(), local_.data(), 3 * staying);
      copy_n(carried_staged_.data(), carried_.data(), width_ * staying);
      copy_n(ids_staged_.data(), ids_.data(), staying);
    }
    copy_n(staged_.data() + 3 * staying, xyz.data(), xyz.size());
    copy_n(carried_staged_.data() + width_ * staying, carried.data(), carried.size());
    copy_n(ids_staged_.data() + staying, ids.data(), arrived);
    std::swap(local_, staged_);
    std::swap(carried_, carried_staged_);
    std::swap(ids_, ids_staged_);
    owned_ = n;
    sorted_ = false;
  }

  void plan_halos(int rank, int ranks, double reach, std::vector<std::uint64_t>& counts) override {
    const std::size_t n = owned_;
    counts.assign(static_cast<std::size_t>(ranks), 0);
    records_ = 0;
    // No axis that halos cross (one rank, every periodic axis local): no record, no pass.
    if (!domains_.crossed[0] && !domains_.crossed[1] && !domains_.crossed[2]) return;
    halo_counts_.resize(n + 1);
    halo_offsets_.resize(n + 1);
    RAYCUT_CUDA_CHECK(cudaMemsetAsync(halo_counts_.data() + n, 0, sizeof(unsigned long long)));
    if (n > 0) {
      count_halos<<<blocks_for(n), 256>>>(domains_, rank, reach, local_.data(), n,
                                          halo_counts_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
    }
    std::size_t temp_bytes = 0;
    RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, halo_counts_.data(),
                                                    halo_offsets_.data(), n + 1));
    temp_.resize(temp_bytes);
    RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(temp_.data(), temp_bytes, halo_counts_.data(),
                                                    halo_offsets_.data(), n + 1));
    unsigned long long total = 0;
    cuda::read_back(&total, halo_offsets_.data() + n, sizeof total, nullptr);
    if (total > 0xFFFFFFFFull)  // the plan's record orders are 32-bit
      throw Error(ErrorCode::out_of_memory,
                  "distributed exchange: " + std::to_string(total) +
                      " halo records on one rank, more than 2^32 - 1; use more ranks");
    records_ = total;
    record_dest_.resize(total);
    record_index_.resize(total);
    record_shift_.resize(3 * std::size_t{total});
    index_.resize(total);
    shift_.resize(3 * std::size_t{total});
    send_.resize(3 * std::size_t{total});
    if (total > 0) {
      write_halos<<<blocks_for(n), 256>>>(domains_, rank, reach, local_.data(), n,
                                          halo_offsets_.data(), record_dest_.data(),
                                          record_index_.data(), record_shift_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
    }
    if (ranks == 1) {  // every record to rank 0, already in order
      counts[0] = total;
      std::swap(index_, record_index_);
      std::swap(shift_, record_shift_);
    } else if (total > 0) {
      order_in_.resize(total);
      order_.resize(total);
      owner_sorted_.resize(total);
      iota<<<blocks_for(total), 256>>>(order_in_.data(), total);
      RAYCUT_CUDA_CHECK_LAUNCH();
      sort_by_key(record_dest_, owner_sorted_, order_in_, order_, total, ranks);
      runs(owner_sorted_.data(), total, ranks, counts);
      gather_records<<<blocks_for(total), 256>>>(order_.data(), total, record_index_.data(),
                                                 record_shift_.data(), index_.data(),
                                                 shift_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
    }
  }

  const std::uint64_t* gather_ids() override {
    send_ids_.resize(records_);
    gather_rows_into(ids_.data(), index_.data(), records_, 1, send_ids_.data());
    return send_ids_.data();
  }

  const std::int32_t* plan_shifts() const override { return shift_.data(); }

  HaloSlots receive_halos(std::size_t count) override {
    halos_ = count;
    // The owned positions stay at the front of local_ (a shrink keeps contents; a growth goes
    // through staged_).
    if (3 * (owned_ + halos_) <= local_.size()) {
      local_.resize(3 * (owned_ + halos_));
    } else {
      staged_.resize(3 * (owned_ + halos_));
      copy_n(staged_.data(), local_.data(), 3 * owned_);
      std::swap(local_, staged_);
    }
    staged_.resize(3 * (owned_ + halos_));  // take()'s other half
    reference_.resize(3 * owned_);
    copy_n(reference_.data(), local_.data(), 3 * owned_);
    halo_ids_.resize(count);
    halo_shifts_.resize(3 * count);
    return {local_.data() + 3 * owned_, halo_ids_.data(), halo_shifts_.data()};
  }

  void download_halos(std::vector<std::uint64_t>& ids,
                      std::vector<std::int32_t>& shifts) const override {
    download_to(ids, halo_ids_.data(), halos_);
    download_to(shifts, halo_shifts_.data(), 3 * halos_);
  }

  Taken take(const float* xyz, const float* carried, float distance) override {
    if (owned_ == 0) return {0, false};
    RAYCUT_CUDA_CHECK(cudaMemsetAsync(report_.data(), 0xFF, 2 * sizeof(unsigned long long)));
    take_positions<<<blocks_for(owned_), 256>>>(xyz, reference_.data(), owned_, distance * distance,
                                                staged_.data(), report_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    unsigned long long report[2];
    cuda::read_back(report, report_.data(), sizeof report, nullptr);
    if (report[0] < owned_) return {static_cast<std::size_t>(report[0]), true};
    // The halos behind the owned positions are all rewritten by the refresh or the exchange
    // that follows, so the staged half becomes the local array as it is.
    std::swap(local_, staged_);
    if (carried) copy_n(carried_.data(), carried, width_ * owned_);
    return {owned_, report[1] == 0};
  }

  const float* gather() override {
    if (records_ > 0) {
      gather_images<<<blocks_for(records_), 256>>>(domains_, local_.data(), index_.data(),
                                                   shift_.data(), records_, send_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
    }
    return send_.data();
  }

  const float* gather_fields(const float* owned, std::size_t width) override {
    fields_send_.resize(width * records_);
    gather_rows_into(owned, index_.data(), records_, width, fields_send_.data());
    return fields_send_.data();
  }

  float* scratch(std::size_t count) override {
    scratch_.resize(count);
    return scratch_.data();
  }

  void copy(void* to, const void* from, std::size_t bytes) const override {
    cuda::copy(to, from, bytes);
  }

  const std::uint64_t* ids() const override { return ids_.data(); }
  const std::uint64_t* halo_ids() const override { return halo_ids_.data(); }
  const std::int32_t* halo_shifts() const override { return halo_shifts_.data(); }
  std::byte* staging(int which, std::size_t bytes) override {
    return staging_[which].at_least(bytes);
  }

  std::size_t owned() const override { return owned_; }
  float* local() override { return local_.data(); }
  const float* carried() const override { return carried_.data(); }

 private:
  // A stable sort of (keys, values) by keys below `keys` (radix: equal keys keep their order).
  void sort_by_key(cuda::DeviceBuffer<std::uint32_t>& keys_in,
                   cuda::DeviceBuffer<std::uint32_t>& keys_out,
                   cuda::DeviceBuffer<std::uint32_t>& values_in,
                   cuda::DeviceBuffer<std::uint32_t>& values_out, std::size_t n, int keys) {
    std::size_t temp_bytes = 0;
    const int bits = bits_for(keys);
    RAYCUT_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, keys_in.data(),
                                                      keys_out.data(), values_in.data(),
                                                      values_out.data(), n, 0, bits));
    temp_.resize(temp_bytes);
    RAYCUT_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp_.data(), temp_bytes, keys_in.data(),
                                                      keys_out.data(), values_in.data(),
                                                      values_out.data(), n, 0, bits));
  }

  // counts[r] = the length of key r's run in sorted keys; the staying run is remembered.
  void runs(const std::uint32_t* sorted, std::size_t n, int keys,
            std::vector<std::uint64_t>& counts) {
    starts_.resize(static_cast<std::size_t>(keys) + 1);
    key_starts<<<blocks_for(static_cast<std::size_t>(keys) + 1), 256>>>(sorted, n, keys,
                                                                        starts_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    std::vector<unsigned long long> starts;
    download_to(starts, starts_.data(), static_cast<std::size_t>(keys) + 1);
    for (int r = 0; r < keys; ++r) counts[static_cast<std::size_t>(r)] = starts[r + 1] - starts[r];
  }

  template <class T>
  void gather_rows_into(const T* from, const std::uint32_t* rows, std::size_t count,
                        std::size_t width, T* to) {
    if (count * width == 0) return;
    gather_rows<<<blocks_for(count * width), 256>>>(from, rows, count, width, to);
    RAYCUT_CUDA_CHECK_LAUNCH();
  }
  void gather(const float* from, const std::uint32_t* rows, std::size_t count, std::size_t width,
              std::vector<float>& to) {
    gather_rows_into(from, rows, count, width, rows_.data());
    download_to(to, rows_.data(), count * width);
  }

  // local_ is what the local engine was built over (owned, then halos); update() writes staged_
  // and swaps them. reference_: the owned positions at the last exchange.
  cuda::DeviceBuffer<float> local_, staged_, reference_, carried_, carried_staged_, send_, rows_;
  cuda::DeviceBuffer<float> fields_send_, scratch_;  // halo fields'
  // The owned particles' global ids (kept in step with local_ by the migrations), the records'
  // to send, the received halos' ids and shifts.
  cuda::DeviceBuffer<std::uint64_t> ids_, ids_staged_, send_ids_, halo_ids_;
  cuda::DeviceBuffer<std::int32_t> halo_shifts_;
  cuda::DeviceBuffer<unsigned long long> report_{2}, starts_;
  cuda::DeviceBuffer<double> cuts_;
  Domains domains_{};
  // The exchange's scratch: owners (or halo destinations) and the orders that sort them.
  cuda::DeviceBuffer<std::uint32_t> owner_, owner_sorted_, order_in_, order_, leaving_;
  cuda::DeviceBuffer<unsigned long long> halo_counts_, halo_offsets_;
  cuda::DeviceBuffer<std::uint32_t> record_dest_, record_index_;
  cuda::DeviceBuffer<std::int32_t> record_shift_;
  cuda::DeviceBuffer<unsigned char> temp_;
  StagingBuffer staging_[2];  // a host transport's send and receive copies
  bool sorted_ = false;       // find_owners sorted: the staying run is order_[staying_first_ ...)
  std::size_t staying_first_ = 0, staying_ = 0;
  // The halo plan: per record the owned index and the shift (3 int32), in send order.
  cuda::DeviceBuffer<std::uint32_t> index_;
  cuda::DeviceBuffer<std::int32_t> shift_;
  std::size_t owned_ = 0, halos_ = 0, records_ = 0, width_ = 0;
};

}  // namespace

std::unique_ptr<DeviceResidence> make_device_residence() {
  return std::make_unique<CudaResidence>();
}

}  // namespace raycut::mpi::detail
