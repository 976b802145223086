// The shared exclusive prefix sum (src/cuda/scan.cuh) against a host sum, from no counts to
// several of CUB's tiles, in place and into another array, for 32- and 64-bit offsets. Skipped
// without a GPU.
#include <cuda_runtime.h>
#include <gtest/gtest.h>

#include <cstdint>
#include <random>
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

const std::uint64_t sizes[] = {0, 1, 1000, 16383, 16384, 16385, 65553, 300000};

TEST(ExclusiveSum, IntoAnotherArrayMatchesTheHostSum) {
  if (!have_gpu()) GTEST_SKIP() << "no CUDA device";
  for (const std::uint64_t n : sizes) {
    const std::vector<std::uint32_t> counts = random_counts(n, static_cast<std::uint32_t>(n));
    Buffer<std::uint32_t> in;
    Buffer<std::uint64_t> out;
    Buffer<unsigned char> temp;
    in.resize(n + 1);
    out.resize(n + 1);
    ASSERT_NE(in.data(), nullptr);
    ASSERT_EQ(
        cudaMemcpy(in.data(), counts.data(), n * sizeof(std::uint32_t), cudaMemcpyHostToDevice),
        cudaSuccess);
    exclusive_sum(in.data(), n, out.data(), temp, nullptr);
    std::vector<std::uint64_t> got(n + 1);
    ASSERT_EQ(
        cudaMemcpy(got.data(), out.data(), (n + 1) * sizeof(std::uint64_t), cudaMemcpyDeviceToHost),
        cudaSuccess);
    EXPECT_EQ(got, host_sum<std::uint64_t>(counts)) << "n = " << n;
  }
}

TEST(ExclusiveSum, InPlaceMatchesTheHostSum) {
  if (!have_gpu()) GTEST_SKIP() << "no CUDA device";
  for (const std::uint64_t n : sizes) {
    const std::vector<std::uint32_t> counts = random_counts(n, static_cast<std::uint32_t>(n) + 7);
    Buffer<std::uint32_t> table;  // n counts and one more entry, for the total
    Buffer<unsigned char> temp;
    table.resize(n + 1);
    ASSERT_NE(table.data(), nullptr);
    ASSERT_EQ(
        cudaMemcpy(table.data(), counts.data(), n * sizeof(std::uint32_t), cudaMemcpyHostToDevice),
        cudaSuccess);
    exclusive_sum(table.data(), n, table.data(), temp, nullptr);
    std::vector<std::uint32_t> got(n + 1);
    ASSERT_EQ(cudaMemcpy(got.data(), table.data(), (n + 1) * sizeof(std::uint32_t),
                         cudaMemcpyDeviceToHost),
              cudaSuccess);
    EXPECT_EQ(got, host_sum<std::uint32_t>(counts)) << "n = " << n;
  }
}

}  // namespace
