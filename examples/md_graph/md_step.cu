// A Lennard-Jones MD loop whose whole step is one CUDA graph: velocity Verlet, the Verlet list
// rebuilt only when a particle has moved more than skin / 2 (a device flag, no host decision),
// and the forces over the list. The host launches the graph and never waits inside a step; it
// reads the list's count back only between blocks of steps, to grow the list if it overflowed.
// Positions stay unwrapped: the pair list takes them as they are, in any periodic image.
//
//   raycut_md_graph [particles=1000] [steps=2000]
// Prints steps per second, rebuilds and the relative drift of the total energy; exits 1 when the
// energy drifts more than 1 % (a broken list loses or invents forces), 77 without a GPU.
#include <cuda_runtime.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

#include "raycut/device_pairs.hpp"
#include "raycut/engine.hpp"

namespace {

constexpr double cutoff = 2.5, skin = 0.3, density = 0.8442, temperature = 0.72, dt = 0.004;

#define CHECK(call)                                                                          \
  do {                                                                                       \
    const cudaError_t status_ = (call);                                                      \
    if (status_ != cudaSuccess) {                                                            \
      std::fprintf(stderr, "%s: %s (%s:%d)\n", #call, cudaGetErrorString(status_), __FILE__, \
                   __LINE__);                                                                \
      std::exit(2);                                                                          \
    }                                                                                        \
  } while (0)

__global__ void kick_drift(double* x, double* v, const double* f, int n) {
  const int k = blockIdx.x * blockDim.x + threadIdx.x;
  if (k >= 3 * n) return;
  v[k] += 0.5 * dt * f[k];
  x[k] += dt * v[k];
}

__global__ void kick(double* v, const double* f, int n) {
  const int k = blockIdx.x * blockDim.x + threadIdx.x;
  if (k < 3 * n) v[k] += 0.5 * dt * f[k];
}

// Forces on i from every listed (i, j, S) within the cutoff (a full list: each pair twice, so
// each row only pushes its own particle), and half the pair energy per entry.
__global__ void lj_forces(const std::int64_t* pi, const std::int64_t* pj, const std::int32_t* s,
                          const std::int64_t* count, std::int64_t capacity, const double* x,
                          double box, double* f, double* energy) {
  const std::int64_t pairs = *count < capacity ? *count : capacity;
  for (std::int64_t p = blockIdx.x * std::int64_t(blockDim.x) + threadIdx.x; p < pairs;
       p += std::int64_t(gridDim.x) * blockDim.x) {
    const std::int64_t i = pi[p], j = pj[p];
    double r[3], r2 = 0;
    for (int k = 0; k < 3; ++k) {
      r[k] = x[3 * j + k] - x[3 * i + k] + s[3 * p + k] * box;
      r2 += r[k] * r[k];
    }
    if (r2 >= cutoff * cutoff) continue;  // in the skin
    const double inv6 = 1 / (r2 * r2 * r2);
    const double push = 24 * inv6 * (2 * inv6 - 1) / r2;  // -dU/dr / r
    for (int k = 0; k < 3; ++k) atomicAdd(&f[3 * i + k], -push * r[k]);
    const double c6 = 1 / pow(cutoff, 6);
    atomicAdd(energy, 0.5 * 4 * (inv6 * (inv6 - 1) - c6 * (c6 - 1)));
  }
}

double total_energy(const std::vector<double>& v, double potential) {
  double kinetic = 0;
  for (double u : v) kinetic += 0.5 * u * u;
  return kinetic + potential;
}

}  // namespace

int main(int argc, char** argv) {
  if (!raycut::cuda_device_available()) {
    std::puts("no CUDA device: nothing to run");
    return 77;
  }
  const int n_side = static_cast<int>(std::lround(std::cbrt(argc > 1 ? std::atof(argv[1]) : 1000)));
  const int steps = argc > 2 ? std::atoi(argv[2]) : 2000;
  if (n_side < 1 || steps < 1) {
    std::fprintf(stderr, "particles must be >= 1 and steps >= 1, got %s and %d\n",
                 argc > 1 ? argv[1] : "1000", steps);
    return 2;
  }
  const int n = n_side * n_side * n_side;
  const double box = std::cbrt(n / density);

  // A simple cubic lattice (no overlaps) and Maxwell velocities without drift.
  std::vector<double> x(3 * n), v(3 * n);
  std::mt19937 rng(1);
  std::normal_distribution<double> gauss(0, std::sqrt(temperature));
  double mean[3] = {0, 0, 0};
  for (int p = 0; p < n; ++p) {
    const int c[3] = {p % n_side, p / n_side % n_side, p / (n_side * n_side)};
    for (int k = 0; k < 3; ++k) {
      x[3 * p + k] = (c[k] + 0.5) * box / n_side;
      v[3 * p + k] = gauss(rng);
      mean[k] += v[3 * p + k] / n;
    }
  }
  for (int p = 0; p < n; ++p)
    for (int k = 0; k < 3; ++k) v[3 * p + k] -= mean[k];
  const double cell[9] = {box, 0, 0, 0, box, 0, 0, 0, box};

  cudaStream_t stream;
  CHECK(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking));
  double *d_x, *d_v, *d_f, *d_energy, *d_cell;
  CHECK(cudaMalloc(&d_x, 3 * n * sizeof(double)));
  CHECK(cudaMalloc(&d_v, 3 * n * sizeof(double)));
  CHECK(cudaMalloc(&d_f, 3 * n * sizeof(double)));
  CHECK(cudaMalloc(&d_energy, sizeof(double)));
  CHECK(cudaMalloc(&d_cell, sizeof cell));
  // On the step's stream: a pageable cudaMemcpy may return before its DMA is done, and work on a
  // non-blocking stream does not wait for it.
  CHECK(cudaMemcpyAsync(d_x, x.data(), 3 * n * sizeof(double), cudaMemcpyHostToDevice, stream));
  CHECK(cudaMemcpyAsync(d_v, v.data(), 3 * n * sizeof(double), cudaMemcpyHostToDevice, stream));
  CHECK(cudaMemcpyAsync(d_cell, cell, sizeof cell, cudaMemcpyHostToDevice, stream));

  raycut::DeviceSystems system;
  system.positions = d_x;
  system.scalar = raycut::Scalar::float64;
  system.size = static_cast<std::size_t>(n);
  system.cells = d_cell;
  system.cell_count = 1;

  const raycut::Context ctx{stream};
  const double sphere = 4.0 / 3.0 * 3.141592653589793 * std::pow(cutoff + skin, 3) * density;
  raycut::DeviceVerletList verlet(ctx, cutoff, skin, static_cast<std::size_t>(1.3 * sphere * n));
  const unsigned blocks = (3 * n + 255) / 256;
  // Device to host on the step's stream, then wait for it: a plain cudaMemcpy runs on the legacy
  // default stream, which does not wait for work on a non-blocking stream.
  auto read = [&](void* host, const void* device, std::size_t bytes) {
    CHECK(cudaMemcpyAsync(host, device, bytes, cudaMemcpyDeviceToHost, stream));
    CHECK(cudaStreamSynchronize(stream));
  };
  auto forces = [&] {
    CHECK(cudaMemsetAsync(d_f, 0, 3 * n * sizeof(double), stream));
    CHECK(cudaMemsetAsync(d_energy, 0, sizeof(double), stream));
    const auto& pairs = verlet.pairs();
    lj_forces<<<1024, 256, 0, stream>>>(pairs.i(), pairs.j(), pairs.shifts(), pairs.count(),
                                        static_cast<std::int64_t>(pairs.capacity()), d_x, box, d_f,
                                        d_energy);
    CHECK(cudaGetLastError());
  };
  // The first list and forces, eagerly: the list's size is known before the capture.
  verlet.update(system);
  if (raycut::read_pair_count(ctx, verlet.pairs().count()) >
      static_cast<std::int64_t>(verlet.pairs().capacity())) {
    std::puts("the initial list overflowed its capacity");
    return 1;
  }
  forces();

  cudaGraph_t graph;
  CHECK(cudaStreamBeginCapture(stream, cudaStreamCaptureModeGlobal));
  kick_drift<<<blocks, 256, 0, stream>>>(d_x, d_v, d_f, n);
  verlet.update(system);
  forces();
  kick<<<blocks, 256, 0, stream>>>(d_v, d_f, n);
  CHECK(cudaStreamEndCapture(stream, &graph));
  cudaGraphExec_t step;
  CHECK(cudaGraphInstantiate(&step, graph, 0));

  double potential = 0;
  read(&potential, d_energy, sizeof potential);  // the eager forces' energy
  const double first = total_energy(v, potential);
  int rebuilds = 0;
  const auto start = std::chrono::steady_clock::now();
  constexpr int block = 50;  // steps between checks of the list's count
  for (int done = 0; done < steps; done += block) {
    for (int s = 0; s < block && done + s < steps; ++s) CHECK(cudaGraphLaunch(step, stream));
    const std::int64_t count = raycut::read_pair_count(ctx, verlet.pairs().count());
    if (count > static_cast<std::int64_t>(verlet.pairs().capacity())) {
      std::printf("the list outgrew its capacity (%lld pairs): grow it and rerun\n",
                  static_cast<long long>(count));
      return 1;
    }
    int rebuilt = 0;
    read(&rebuilt, verlet.rebuilt(), sizeof rebuilt);
    rebuilds += rebuilt;  // sampled: the last step of each block
  }
  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  read(v.data(), d_v, 3 * n * sizeof(double));
  read(&potential, d_energy, sizeof potential);
  const double last = total_energy(v, potential);
  const double drift = std::fabs(last - first) / std::fabs(first);
  std::printf(
      "%d particles, %d steps in one graph each: %.1f us per step, rebuilt at %d of %d "
      "sampled steps, energy %.6f -> %.6f (relative drift %.2e)\n",
      n, steps, 1e6 * seconds / steps, rebuilds, (steps + block - 1) / block, first / n, last / n,
      drift);
  cudaGraphExecDestroy(step);
  cudaGraphDestroy(graph);
  return drift < 1e-2 ? 0 : 1;
}
