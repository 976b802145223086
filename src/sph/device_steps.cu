#include "sph/device_steps.hpp"

#include <cuda_runtime.h>

#include <string>

#include "raycut/error.hpp"

namespace raycut::sph::device {
namespace {

// The SPH library sees the engine's public API only: its own small check of CUDA calls, throwing
// raycut::Error as the engine's methods do (out_of_memory for a failed allocation, else backend).
void check(cudaError_t status, const char* call, int line) {
  if (status == cudaSuccess) return;
  const ErrorCode code =
      status == cudaErrorMemoryAllocation ? ErrorCode::out_of_memory : ErrorCode::backend;
  throw Error(code, std::string("CUDA error '") + cudaGetErrorString(status) + "' in " + call +
                        " at " + __FILE__ + ":" + std::to_string(line));
}
#define SPH_CUDA_CHECK(call) check((call), #call, __LINE__)
// After a kernel launch: launch-configuration errors surface here, not at the next sync.
#define SPH_CUDA_CHECK_LAUNCH() SPH_CUDA_CHECK(cudaGetLastError())

constexpr unsigned block = 256;

unsigned blocks_for(std::size_t n) {
  return static_cast<unsigned>((n + block - 1) / block);
}

__global__ void density_and_pressure_kernel(const float* __restrict__ neighbour_density,
                                            float* __restrict__ rho, float* __restrict__ p,
                                            std::size_t n, StepConstants c) {
  const std::size_t i = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
  if (i >= n) return;
  const float r = density_with_self(neighbour_density ? neighbour_density[i] : 0.0f, c);
  rho[i] = r;
  p[i] = pressure_of(r, c);
}

__global__ void integrate_kernel(float* __restrict__ x, float* __restrict__ v,
                                 const float* __restrict__ force, const float* __restrict__ rho,
                                 const float* __restrict__ fixed, std::size_t n, StepConstants c) {
  const std::size_t i = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
  if (i >= n) return;
  float xi[3] = {x[3 * i], x[3 * i + 1], x[3 * i + 2]};
  float vi[3] = {v[3 * i], v[3 * i + 1], v[3 * i + 2]};
  const float zero[3] = {0.0f, 0.0f, 0.0f};
  const float fi[3] = {force ? force[3 * i] : 0.0f, force ? force[3 * i + 1] : 0.0f,
                       force ? force[3 * i + 2] : 0.0f};
  if (fixed) {
    if (fixed[i] != 0.0f) return;  // boundary particle: never moves
    integrate_or_hold(xi, vi, force ? fi : zero, rho[i], 0.0f, c);
  } else {
    integrate_particle(xi, vi, force ? fi : zero, rho[i], c);
  }
  for (int k = 0; k < 3; ++k) {
    x[3 * i + k] = xi[k];
    v[3 * i + k] = vi[k];
  }
}

}  // namespace

void density_and_pressure(const float* neighbour_density, float* rho, float* p, std::size_t n,
                          const StepConstants& c) {
  if (n == 0) return;
  density_and_pressure_kernel<<<blocks_for(n), block>>>(neighbour_density, rho, p, n, c);
  SPH_CUDA_CHECK_LAUNCH();
}

void integrate(float* x, float* v, const float* force, const float* rho, const float* fixed,
               std::size_t n, const StepConstants& c) {
  if (n == 0) return;
  integrate_kernel<<<blocks_for(n), block>>>(x, v, force, rho, fixed, n, c);
  SPH_CUDA_CHECK_LAUNCH();
}

void copy_to_host(float* host, const float* device_values, std::size_t n) {
  if (n == 0) return;
  SPH_CUDA_CHECK(cudaMemcpy(host, device_values, n * sizeof(float), cudaMemcpyDeviceToHost));
}

void synchronize() {
  SPH_CUDA_CHECK(cudaDeviceSynchronize());
}

}  // namespace raycut::sph::device
