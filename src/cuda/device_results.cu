#include <thrust/iterator/counting_iterator.h>
#include <thrust/iterator/transform_iterator.h>

#include <cub/device/device_scan.cuh>

#include "cuda/device_results.cuh"

namespace raycut::detail::cuda {

OutputView DeviceResults::prepare(Kernel kernel, std::size_t n) {
  kernel_ = kernel;
  n_ = n;
  OutputView view;
  const KernelOutputs produces = outputs_of(kernel);
  if (produces.count) {
    count_.resize(n);
    view.count = count_.data();
  }
  if (produces.energy) {
    energy_.resize(n);
    view.energy = energy_.data();
  }
  if (produces.force) {
    force_.resize(3 * n);
    view.force = force_.data();
  }
  return view;
}

Results DeviceResults::to_host() const {
  Results out;
  auto copy = [](auto& host, const auto& device, std::size_t count) {
    host.resize(count);
    RAYCUT_CUDA_CHECK(
        cudaMemcpy(host.data(), device.data(), count * sizeof(host[0]), cudaMemcpyDeviceToHost));
  };
  const KernelOutputs produces = outputs_of(kernel_);
  if (produces.count) copy(out.count, count_, n_);
  if (produces.energy) copy(out.energy, energy_, n_);
  if (produces.force) copy(out.force, force_, 3 * n_);
  return out;
}

ResultsView DeviceResults::view() const {
  const KernelOutputs produces = outputs_of(kernel_);
  return {produces.count ? count_.data() : nullptr, produces.energy ? energy_.data() : nullptr,
          produces.force ? force_.data() : nullptr, MemorySpace::device};
}

EventTimer::EventTimer() {
  RAYCUT_CUDA_CHECK(cudaEventCreate(&start_));
  RAYCUT_CUDA_CHECK(cudaEventCreate(&stop_));
}

EventTimer::~EventTimer() {
  cudaEventDestroy(start_);
  cudaEventDestroy(stop_);
}

void EventTimer::start(cudaStream_t stream) {
  RAYCUT_CUDA_CHECK(cudaEventRecord(start_, stream));
  started_ = true;
}

void EventTimer::stop(cudaStream_t stream) {
  RAYCUT_CUDA_CHECK(cudaEventRecord(stop_, stream));
}

double EventTimer::elapsed_ms() const {
  if (!started_) return -1;
  RAYCUT_CUDA_CHECK(cudaEventSynchronize(stop_));
  float ms = 0;
  RAYCUT_CUDA_CHECK(cudaEventElapsedTime(&ms, start_, stop_));
  return ms;
}

namespace {
// Scanning n+1 inputs, the last a zero, writes the total into offsets[n] too.
struct CountOrZero {
  const std::uint32_t* counts;
  std::size_t n;
  __host__ __device__ std::uint64_t operator()(std::size_t i) const {
    return i < n ? counts[i] : 0;
  }
};
}  // namespace

void exclusive_scan(const std::uint32_t* counts, std::uint64_t* offsets, std::size_t n) {
  const auto input = thrust::make_transform_iterator(thrust::counting_iterator<std::size_t>(0),
                                                     CountOrZero{counts, n});
  std::size_t temp_bytes = 0;
  RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, input, offsets, n + 1));
  DeviceBuffer<unsigned char> temp(temp_bytes);
  RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(temp.data(), temp_bytes, input, offsets, n + 1));
}

}  // namespace raycut::detail::cuda
