// The device-resident distributed SPH solver's state (sph_device.hpp).
#include <cuda_runtime.h>

#include "cuda/device_buffer.cuh"
#include "cuda/runtime.hpp"
#include "mpi/sph_device.hpp"
#include "sph/device_steps.hpp"

namespace raycut::mpi::detail {
namespace {

namespace cuda = raycut::detail::cuda;

unsigned blocks_for(std::size_t n) {
  return static_cast<unsigned>((n + 255) / 256);
}

// carried[w i ..] = v[3 i ..] (and fixed[i] when w == 4), or the reverse.
__global__ void pack_kernel(const float* v, const float* fixed, std::size_t n, int w,
                            float* carried) {
  const std::size_t i = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
  if (i >= n) return;
  for (int c = 0; c < 3; ++c) carried[w * i + c] = v[3 * i + c];
  if (w == 4) carried[w * i + 3] = fixed[i];
}

__global__ void unpack_kernel(const float* carried, std::size_t n, int w, float* v, float* fixed) {
  const std::size_t i = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
  if (i >= n) return;
  for (int c = 0; c < 3; ++c) v[3 * i + c] = carried[w * i + c];
  if (w == 4) fixed[i] = carried[w * i + 3];
}

using raycut::detail::cuda::copy;

class CudaSph final : public SphDevice {
 public:
  void upload(const std::vector<float>& x, const std::vector<float>& v,
              const std::vector<float>& fixed, bool with_fixed) override {
    width_ = with_fixed ? 4 : 3;
    resize(x.size() / 3);
    copy(x_.data(), x.data(), x.size() * sizeof(float));
    copy(v_.data(), v.data(), v.size() * sizeof(float));
    if (with_fixed) copy(fixed_.data(), fixed.data(), fixed.size() * sizeof(float));
  }

  void take(const float* positions, const float* carried, std::size_t n) override {
    resize(n);
    copy(x_.data(), positions, 3 * n * sizeof(float));
    if (n == 0) return;
    unpack_kernel<<<blocks_for(n), 256>>>(carried, n, static_cast<int>(width_), v_.data(),
                                          fixed_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
  }

  const float* pack() override {
    carried_.resize(width_ * n_);
    if (n_ > 0) {
      pack_kernel<<<blocks_for(n_), 256>>>(v_.data(), fixed_.data(), n_, static_cast<int>(width_),
                                           carried_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
    }
    return carried_.data();
  }

  std::size_t width() const override { return width_; }
  std::size_t size() const override { return n_; }
  float* x() override { return x_.data(); }
  float* v() override { return v_.data(); }
  float* rho() override { return rho_.data(); }
  float* p() override { return p_.data(); }
  const float* fixed() const override { return width_ == 4 ? fixed_.data() : nullptr; }

  void density_and_pressure(const float* neighbour_density, const sph::StepConstants& c) override {
    sph::device::density_and_pressure(neighbour_density, rho_.data(), p_.data(), n_, c);
  }

  void integrate(const float* force, const sph::StepConstants& c) override {
    sph::device::integrate(x_.data(), v_.data(), force, rho_.data(), fixed(), n_, c);
    sph::device::synchronize();  // the step's timings end with its work, as sph::Solver's
  }

  void download(std::vector<float>& x, std::vector<float>& v, std::vector<float>& rho,
                std::vector<float>& p) const override {
    x.resize(3 * n_);
    v.resize(3 * n_);
    rho.resize(n_);
    p.resize(n_);
    copy(x.data(), x_.data(), x.size() * sizeof(float));
    copy(v.data(), v_.data(), v.size() * sizeof(float));
    copy(rho.data(), rho_.data(), rho.size() * sizeof(float));
    copy(p.data(), p_.data(), p.size() * sizeof(float));
  }

 private:
  // Contents are not kept (DeviceBuffer); rho and p are remade by the next density pass.
  void resize(std::size_t n) {
    n_ = n;
    x_.resize(3 * n);
    v_.resize(3 * n);
    rho_.resize(n);
    p_.resize(n);
    fixed_.resize(width_ == 4 ? n : 0);
  }

  cuda::DeviceBuffer<float> x_, v_, rho_, p_, fixed_, carried_;
  std::size_t n_ = 0, width_ = 3;
};

}  // namespace

std::unique_ptr<SphDevice> make_sph_device() {
  return std::make_unique<CudaSph>();
}

}  // namespace raycut::mpi::detail
