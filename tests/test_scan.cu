// The shared exclusive prefix sum (src/cuda/scan.cuh) against a host sum, from no counts to
// several of CUB's tiles, in place and into another array, for 32- and 64-bit offsets. Skipped
// without a GPU.
#include <cuda_runtime.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
#include <type_traits>
#include <vector>

#include "cuda/scan.cuh"

namespace {

using raycut::detail::cuda::exclusive_sum;

bool have_gpu() {
  int devices = 0;
  return cudaGetDeviceCount(&devices) == cudaSuccess && devices > 0;
}

// A device buffer of T that frees itself; resize() and data() as exclusive_sum's storage wants.
template <class T>
struct Buffer {
  T* p = nullptr;
  std::size_t size = 0;
  ~Buffer() { cudaFree(p); }
  void resize(std::size_t n) {
    if (n <= size) return;
    cudaFree(p);
    p = nullptr;
    size = 0;
    if (cudaMalloc(&p, n * sizeof(T)) == cudaSuccess) size = n;
  }
  T* data() { return p; }
};

std::vector<std::uint32_t> random_counts(std::uint64_t n, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<std::uint32_t> count(0, 300);
  std::vector<std::uint32_t> c(n);
  for (auto& v : c) v = count(rng);
  return c;
}

template <class Offset>
std::vector<Offset> host_sum(const std::vector<std::uint32_t>& counts) {
  std::vector<Offset> o(counts.size() + 1, 0);
  for (std::size_t i = 0; i < counts.size(); ++i) o[i + 1] = o[i] + counts[i];
  return o;
}

// The device's sum of `counts` as Offset: into a second array, or in place (where Offset is the
// counts' type). Empty where a CUDA call failed.
template <class Offset>
std::vector<Offset> device_sum(const std::vector<std::uint32_t>& counts, bool in_place) {
  const std::uint64_t n = counts.size();
  Buffer<std::uint32_t> in;  // n counts, and room for the total when summed in place
  Buffer<Offset> out;
  Buffer<unsigned char> temp;
  in.resize(n + 1);
  out.resize(n + 1);
  if (!in.data() || !out.data() ||
      cudaMemcpy(in.data(), counts.data(), n * sizeof(std::uint32_t), cudaMemcpyHostToDevice) !=
          cudaSuccess)
    return {};
  Offset* result = out.data();
  if constexpr (std::is_same_v<Offset, std::uint32_t>)
    if (in_place) result = in.data();
  exclusive_sum(in.data(), n, result, temp, nullptr);
  std::vector<Offset> got(n + 1);
  if (cudaMemcpy(got.data(), result, (n + 1) * sizeof(Offset), cudaMemcpyDeviceToHost) !=
      cudaSuccess)
    return {};
  return got;
}

const std::uint64_t sizes[] = {0, 1, 1000, 16383, 16384, 16385, 65553, 300000};

TEST(ExclusiveSum, IntoAnotherArrayMatchesTheHostSum) {
  if (!have_gpu()) GTEST_SKIP() << "no CUDA device";
  for (const std::uint64_t n : sizes) {
    const std::vector<std::uint32_t> counts = random_counts(n, static_cast<std::uint32_t>(n));
    EXPECT_EQ(device_sum<std::uint64_t>(counts, false), host_sum<std::uint64_t>(counts))
        << "n = " << n;
  }
}

TEST(ExclusiveSum, InPlaceMatchesTheHostSum) {
  if (!have_gpu()) GTEST_SKIP() << "no CUDA device";
  for (const std::uint64_t n : sizes) {
    const std::vector<std::uint32_t> counts = random_counts(n, static_cast<std::uint32_t>(n) + 7);
    EXPECT_EQ(device_sum<std::uint32_t>(counts, true), host_sum<std::uint32_t>(counts))
        << "n = " << n;
  }
}

}  // namespace
