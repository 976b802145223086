// The device side of a device-resident DistributedEngine (device_residence.hpp).
#include <cuda_runtime.h>

#include <algorithm>

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

unsigned blocks_for(std::size_t n) {
  return static_cast<unsigned>(std::clamp<std::size_t>((n + 255) / 256, 1, 4096));
}

template <class T>
void copy_in(cuda::DeviceBuffer<T>& buffer, const T* host, std::size_t count) {
  buffer.resize(count);
  if (count > 0)
    RAYCUT_CUDA_CHECK(
        cudaMemcpy(buffer.data(), host, count * sizeof(T), cudaMemcpyHostToDevice));
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

  std::size_t take(const float* xyz, const float* carried) override {
    // Checked where they are, so that a refused update leaves the engine's positions as they were.
    const std::size_t bad = cuda::first_non_finite(xyz, owned_, nullptr);
    if (bad < owned_) return bad;
    copy_on_device(local_.data(), xyz, 3 * owned_);
    if (carried) copy_on_device(carried_.data(), carried, width_ * owned_);
    return owned_;
  }

  bool moved_beyond(float distance) const override {
    return cuda::moved_beyond(local_.data(), reference_.data(), owned_, distance, nullptr);
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
      RAYCUT_CUDA_CHECK(
          cudaMemcpy(to, from, count * sizeof(float), cudaMemcpyDeviceToDevice));
  }

  cuda::DeviceBuffer<float> local_, reference_, carried_, send_;
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
