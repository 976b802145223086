// Shifted-force Coulomb through raycut::cuda::for_each_pair on "auto": the grid on the GPU when
// a CUDA device is present (inputs and outputs in device memory), else the CPU cell list through
// the same call (host memory). Checked against a double-precision O(N^2) loop; exits 1 when off.
#include <cuda_runtime.h>
#include <raycut/cuda/pairs.cuh>
#include <raycut/engine.hpp>

#include <cstdio>
#include <cstdlib>
#include <vector>

#include "coulomb.hpp"

namespace {

void check(cudaError_t status, const char* what) {
  if (status != cudaSuccess) {
    std::fprintf(stderr, "%s: %s\n", what, cudaGetErrorString(status));
    std::exit(2);
  }
}

// A float array in device memory.
struct DeviceFloats {
  float* p = nullptr;
  explicit DeviceFloats(std::size_t n) { check(cudaMalloc(&p, n * sizeof(float)), "cudaMalloc"); }
  DeviceFloats(const DeviceFloats&) = delete;
  ~DeviceFloats() { cudaFree(p); }
};

}  // namespace

int main() {
  const coulomb::System s = coulomb::make_system(20000, 0.25f);
  const std::size_t n = s.charge.size();
  std::vector<float> energy(n), force(3 * n);

  raycut::Engine engine("auto");  // grid with a GPU, cell-list without
  if (engine.space() == raycut::MemorySpace::device) {
    DeviceFloats xyz(3 * n), charge(n), d_energy(n), d_force(3 * n);
    check(cudaMemcpy(xyz.p, s.xyz.data(), 3 * n * sizeof(float), cudaMemcpyHostToDevice), "copy");
    check(cudaMemcpy(charge.p, s.charge.data(), n * sizeof(float), cudaMemcpyHostToDevice), "copy");
    engine.build({xyz.p, n, raycut::MemorySpace::device}, s.cutoff);
    raycut::cuda::for_each_pair(
        engine, coulomb::ShiftedForce::make(charge.p, s.cutoff, d_energy.p, d_force.p));
    check(cudaDeviceSynchronize(), "kernel");  // queued on the engine's stream
    check(cudaMemcpy(energy.data(), d_energy.p, n * sizeof(float), cudaMemcpyDeviceToHost), "copy");
    check(cudaMemcpy(force.data(), d_force.p, 3 * n * sizeof(float), cudaMemcpyDeviceToHost),
          "copy");
  } else {
    std::printf("no CUDA device: running %s through raycut::cuda::for_each_pair on the host\n",
                engine.method().c_str());
    engine.build({s.xyz.data(), n, raycut::MemorySpace::host}, s.cutoff);
    raycut::cuda::for_each_pair(engine, coulomb::ShiftedForce::make(s.charge.data(), s.cutoff,
                                                                    energy.data(), force.data()));
  }

  double total = 0;
  for (float e : energy) total += e;
  const double worst = coulomb::worst_error(s, energy, force);
  std::printf("%s: %zu particles, total energy %.6f, worst relative error %.2e\n",
              engine.method().c_str(), n, total, worst);
  return worst < 1e-4 ? 0 : 1;
}
