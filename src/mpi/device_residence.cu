// The device side of a device-resident DistributedEngine (device_residence.hpp).
#include <cuda_runtime.h>

#include <algorithm>
#include <utility>

#include "cuda/device_buffer.cuh"
#include "cuda/runtime.hpp"
#include "mpi/device_residence.hpp"

namespace raycut::mpi::detail {
namespace {

namespace cuda = raycut::detail::cuda;

struct Cell {
  double rows[9];  // row-major: rows[3 r + c] = cell[r][c]
};

// x + S . cell in double, rounded to float; the same operations in the same order as the host's
// image() (distributed.cpp), without contraction into FMAs, so halos are bit-identical whichever
// side makes them.
__global__ void gather_images(const float* xyz, const std::uint32_t* index,
                              const std::int32_t* shift, std::size_t records, Cell cell,
                              float* out) {
  for (std::size_t k = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x; k < records;
       k += std::size_t{gridDim.x} * blockDim.x) {
    const float* x = xyz + 3 * std::size_t{index[k]};
    const std::int32_t* s = shift + 3 * k;
    const bool zero = s[0] == 0 && s[1] == 0 && s[2] == 0;
    for (int c = 0; c < 3; ++c) {
      double v = x[c];
      if (!zero)
        for (int row = 0; row < 3; ++row)
          v = __dadd_rn(v, __dmul_rn(static_cast<double>(s[row]), cell.rows[3 * row + c]));
      out[3 * k + c] = zero ? x[c] : __double2float_rn(v);
    }
  }
}

// update()'s pass over the owned particles: the new positions into `out` (the other half of a
// double buffer), the first non-finite coordinate (atomicMin over report[0], which starts at
// all ones) and whether one moved more than the skin's half (report[1] set to 0, from all ones),
// with the float arithmetic of the engine's own moved_beyond (runtime.cu).
__global__ void take_positions(const float* xyz, const float* reference, std::size_t n,
                               float limit_squared, float* out, unsigned long long* report) {
  for (std::size_t i = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x; i < n;
       i += std::size_t{gridDim.x} * blockDim.x) {
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

unsigned blocks_for(std::size_t n) {
  return static_cast<unsigned>(std::clamp<std::size_t>((n + 255) / 256, 1, 4096));
}

template <class T>
void copy_in(cuda::DeviceBuffer<T>& buffer, const T* host, std::size_t count) {
  buffer.resize(count);
  if (count > 0)
    RAYCUT_CUDA_CHECK(cudaMemcpy(buffer.data(), host, count * sizeof(T), cudaMemcpyHostToDevice));
}

class CudaResidence final : public DeviceResidence {
 public:
  void adopt(const float* xyz, const float* carried, std::size_t owned, std::size_t width,
             std::vector<float>& host_xyz, std::vector<float>& host_carried) override {
    owned_ = owned;
    width_ = width;
    local_.resize(3 * owned);
    carried_.resize(width * owned);
    copy_on_device(local_.data(), xyz, 3 * owned);
    copy_on_device(carried_.data(), carried, width * owned);
    download(host_xyz, host_carried);
  }

  void upload(const std::vector<float>& local_xyz, std::size_t owned,
              const std::vector<float>& carried, const std::vector<std::uint32_t>& index,
              const std::vector<std::int32_t>& shift,
              const std::array<std::array<double, 3>, 3>& cell) override {
    owned_ = owned;
    halos_ = local_xyz.size() / 3 - owned;
    width_ = owned > 0 ? carried.size() / owned : 0;
    records_ = index.size();
    for (int row = 0; row < 3; ++row)
      for (int c = 0; c < 3; ++c) cell_.rows[3 * row + c] = cell[row][c];
    copy_in(local_, local_xyz.data(), local_xyz.size());
    staged_.resize(local_xyz.size());
    reference_.resize(3 * owned);
    copy_on_device(reference_.data(), local_.data(), 3 * owned);
    copy_in(carried_, carried.data(), carried.size());
    copy_in(index_, index.data(), index.size());
    copy_in(shift_, shift.data(), shift.size());
    send_.resize(3 * records_);
  }

  void download(std::vector<float>& xyz, std::vector<float>& carried) const override {
    xyz.resize(3 * owned_);
    carried.resize(width_ * owned_);
    if (!xyz.empty()) cuda::download(xyz.data(), local_.data(), xyz.size() * sizeof(float));
    if (!carried.empty())
      cuda::download(carried.data(), carried_.data(), carried.size() * sizeof(float));
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
    if (carried) copy_on_device(carried_.data(), carried, width_ * owned_);
    return {owned_, report[1] == 0};
  }

  const float* gather() override {
    if (records_ > 0) {
      gather_images<<<blocks_for(records_), 256>>>(local_.data(), index_.data(), shift_.data(),
                                                   records_, cell_, send_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
    }
    return send_.data();
  }

  void upload_halos(const float* xyz) override {
    if (halos_ > 0)
      RAYCUT_CUDA_CHECK(cudaMemcpy(local_.data() + 3 * owned_, xyz, 3 * halos_ * sizeof(float),
                                   cudaMemcpyHostToDevice));
  }

  void download_gathered(std::vector<float>& xyz) const override {
    xyz.resize(3 * records_);
    if (!xyz.empty()) cuda::download(xyz.data(), send_.data(), xyz.size() * sizeof(float));
  }

  std::size_t owned() const override { return owned_; }
  float* local() override { return local_.data(); }
  const float* carried() const override { return carried_.data(); }

 private:
  // Reallocates when growing (DeviceBuffer); the legacy stream orders every copy.
  static void copy_on_device(float* to, const float* from, std::size_t count) {
    if (count > 0)
      RAYCUT_CUDA_CHECK(cudaMemcpy(to, from, count * sizeof(float), cudaMemcpyDeviceToDevice));
  }

  // local_ is what the local engine was built over; update() writes staged_ and swaps them.
  cuda::DeviceBuffer<float> local_, staged_, reference_, carried_, send_;
  cuda::DeviceBuffer<unsigned long long> report_{2};
  cuda::DeviceBuffer<std::uint32_t> index_;
  cuda::DeviceBuffer<std::int32_t> shift_;
  std::size_t owned_ = 0, halos_ = 0, records_ = 0, width_ = 0;
  Cell cell_{};
};

}  // namespace

std::unique_ptr<DeviceResidence> make_device_residence() {
  return std::make_unique<CudaResidence>();
}

}  // namespace raycut::mpi::detail
