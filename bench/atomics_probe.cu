// How fast are the source-side atomics a half list (Newton's third law) would need? A probe, not
// part of the build: each of N = 2^20 threads adds 67 terms (half of the ~134 neighbours at beta
// = 32, p = 32) to targets at pseudo-random slots within +-32768 of its own (the span of its 25
// rows in cell order), as 64-bit fixed-point integer atomics (order-independent sums), as float
// atomics, and into a register only (the loop without atomics). docs/grid.md quotes the result.
//
//   nvcc -O3 -arch=sm_90 bench/atomics_probe.cu -o atomics_probe && ./atomics_probe
#include <cuda_runtime.h>

#include <cstdio>

constexpr int n = 1 << 20, per_thread = 67, window = 32768;

__device__ unsigned hash(unsigned x) {
  x ^= x >> 16;
  x *= 0x7feb352dU;
  x ^= x >> 15;
  x *= 0x846ca68bU;
  return x ^ (x >> 16);
}

template <int Mode>
__global__ void probe(unsigned long long* fixed, float* floats, float* sink) {
  const unsigned t = blockIdx.x * blockDim.x + threadIdx.x;
  if (t >= n) return;
  float own = 0.0f;
  for (int k = 0; k < per_thread; ++k) {
    const unsigned h = hash(t * per_thread + k);
    const unsigned j = (t + n + (h % (2 * window)) - window) % n;
    const float term = 1.0f / (1.0f + (h & 1023));
    own += term;
    if (Mode == 1) atomicAdd(&fixed[j], static_cast<unsigned long long>(term * 4294967296.0f));
    if (Mode == 2) atomicAdd(&floats[j], term);
  }
  sink[t] = own;
}

template <int Mode>
float time_ms(unsigned long long* fixed, float* floats, float* sink) {
  cudaEvent_t a, b;
  cudaEventCreate(&a);
  cudaEventCreate(&b);
  probe<Mode><<<n / 128, 128>>>(fixed, floats, sink);  // warm-up
  float best = 1e30f;
  for (int r = 0; r < 5; ++r) {
    cudaEventRecord(a);
    probe<Mode><<<n / 128, 128>>>(fixed, floats, sink);
    cudaEventRecord(b);
    cudaEventSynchronize(b);
    float ms = 0;
    cudaEventElapsedTime(&ms, a, b);
    best = ms < best ? ms : best;
  }
  return best;
}

int main() {
  unsigned long long* fixed;
  float *floats, *sink;
  cudaMalloc(&fixed, n * sizeof(unsigned long long));
  cudaMalloc(&floats, n * sizeof(float));
  cudaMalloc(&sink, n * sizeof(float));
  cudaMemset(fixed, 0, n * sizeof(unsigned long long));
  cudaMemset(floats, 0, n * sizeof(float));
  const double atomics = double(n) * per_thread;
  const float none = time_ms<0>(fixed, floats, sink), fixed64 = time_ms<1>(fixed, floats, sink),
              f32 = time_ms<2>(fixed, floats, sink);
  std::printf("atomics,%.0f\nno atomics (loop only) ms,%.4f\n", atomics, none);
  std::printf("64-bit integer atomics ms,%.4f,%.1f G/s\n", fixed64, atomics / fixed64 / 1e6);
  std::printf("float atomics ms,%.4f,%.1f G/s\n", f32, atomics / f32 / 1e6);
  return cudaGetLastError() == cudaSuccess ? 0 : 1;
}
