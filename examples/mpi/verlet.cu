// lj_md --device's integrator kernels (verlet.hpp).
#include <cuda_runtime.h>

#include <stdexcept>
#include <string>

#include "verlet.hpp"

namespace lj_md {
namespace {

void check(cudaError_t status, const char* what) {
  if (status != cudaSuccess)
    throw std::runtime_error(std::string(what) + ": " + cudaGetErrorString(status));
}

unsigned blocks(std::size_t floats) {
  return static_cast<unsigned>((floats + 255) / 256);
}

__global__ void kick_drift_kernel(const float* x, const float* v, const float* f, std::size_t m,
                                  float half, float dt, float* x_out, float* v_out) {
  const std::size_t k = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
  if (k >= m) return;
  const float u = v[k] + half * f[k];
  v_out[k] = u;
  x_out[k] = x[k] + dt * u;
}

__global__ void kick_kernel(const float* v, const float* f, std::size_t m, float half,
                            float* v_out) {
  const std::size_t k = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
  if (k < m) v_out[k] = v[k] + half * f[k];
}

}  // namespace

void kick_drift(const float* x, const float* v, const float* f, std::size_t n, float half, float dt,
                float* x_out, float* v_out) {
  if (n == 0) return;
  kick_drift_kernel<<<blocks(3 * n), 256>>>(x, v, f, 3 * n, half, dt, x_out, v_out);
  check(cudaGetLastError(), "kick_drift");
}

void kick(const float* v, const float* f, std::size_t n, float half, float* v_out) {
  if (n == 0) return;
  kick_kernel<<<blocks(3 * n), 256>>>(v, f, 3 * n, half, v_out);
  check(cudaGetLastError(), "kick");
}

DeviceFloats::~DeviceFloats() {
  cudaFree(data_);
}

float* DeviceFloats::resize(std::size_t count) {
  if (count > capacity_) {
    check(cudaFree(data_), "cudaFree");
    data_ = nullptr;
    check(cudaMalloc(&data_, count * sizeof(float)), "cudaMalloc");
    capacity_ = count;
  }
  return data_;
}

void DeviceFloats::upload(const float* host, std::size_t count) {
  resize(count);
  if (count > 0)
    check(cudaMemcpy(data_, host, count * sizeof(float), cudaMemcpyHostToDevice), "cudaMemcpy");
}

void DeviceFloats::copy(const float* device, std::size_t count) {
  resize(count);
  if (count > 0)
    check(cudaMemcpy(data_, device, count * sizeof(float), cudaMemcpyDeviceToDevice), "cudaMemcpy");
}

void DeviceFloats::download(float* host, std::size_t count) const {
  if (count > 0)
    check(cudaMemcpy(host, data_, count * sizeof(float), cudaMemcpyDeviceToHost), "cudaMemcpy");
}

bool have_device() {
  int count = 0;
  return cudaGetDeviceCount(&count) == cudaSuccess && count > 0;
}

}  // namespace lj_md
