#include <algorithm>
#include <string>

#include "core/validation.hpp"
#include "cuda/device_results.cuh"
#include "cuda/runtime.hpp"
#include "cuda/scan.cuh"
#include "raycut/host_memory.hpp"

namespace raycut::detail::cuda {
namespace {

template <class T, Allocation A>
T* sized(DeviceBuffer<T, A>& buffer, std::size_t count, bool wanted) {
  if (!wanted) return nullptr;
  buffer.resize(count);
  return buffer.data();
}

template <class T>
void copy_to_host(std::vector<T>& host, const T* device, std::size_t count) {
  host.resize(count);
  if (count > 0)
    RAYCUT_CUDA_CHECK(cudaMemcpy(host.data(), device, count * sizeof(T), cudaMemcpyDeviceToHost));
}

}  // namespace

KernelOutputs DeviceResults::prepare(Kernel kernel, std::size_t n) {
  kernel_ = kernel;
  n_ = n;
  valid_ = false;
  const KernelProduces p = produces(kernel);
  return {sized(count_, n, p.count), sized(energy_, n, p.energy), sized(force_, 3 * n, p.force),
          sized(virial_, 6 * n, p.virial), sized(density_, n, p.density)};
}

Results DeviceResults::to_host() const {
  if (!valid_) throw Error(ErrorCode::internal, "no results: the last compute failed");
  Results out;
  const KernelProduces p = produces(kernel_);
  if (p.count) copy_to_host(out.count, count_.data(), n_);
  if (p.energy) copy_to_host(out.energy, energy_.data(), n_);
  if (p.force) copy_to_host(out.force, force_.data(), 3 * n_);
  if (p.virial) copy_to_host(out.virial, virial_.data(), 6 * n_);
  if (p.density) copy_to_host(out.density, density_.data(), n_);
  return out;
}

ResultsView DeviceResults::view() const {
  if (!valid_) throw Error(ErrorCode::internal, "no results: the last compute failed");
  const KernelProduces p = produces(kernel_);
  return {p.count ? count_.data() : nullptr,     p.energy ? energy_.data() : nullptr,
          p.force ? force_.data() : nullptr,     p.virial ? virial_.data() : nullptr,
          p.density ? density_.data() : nullptr, MemorySpace::device};
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

// ---- device lists ------------------------------------------------------------------------------

std::size_t DeviceListStorage::bytes() const {
  return counts_.bytes() + offsets_.bytes() + indices_.bytes() + distances_.bytes() +
         vectors_.bytes() + shifts_.bytes() + rows_.bytes() + columns_.bytes() + scan_temp_.bytes();
}

NeighbourList DeviceListStorage::to_host() const {
  // The host copy is budgeted as every host allocation is (RAYCUT_MAX_MEMORY): a list that fits
  // the device may not fit the host, and overcommit would let the copy be killed, not refused.
  require_host_memory(
      8.0 * static_cast<double>(n + 1) + bytes_per_entry(options) * static_cast<double>(pairs),
      "a host copy of a neighbour list of " + std::to_string(pairs) + " pairs");
  NeighbourList list;
  copy_to_host(list.offsets, offsets, n + 1);
  if (options.coo) {
    copy_to_host(list.rows, rows, pairs);
    copy_to_host(list.columns, columns, pairs);
  } else {
    allocate_indices(list, pairs);
    if (pairs > 0)
      RAYCUT_CUDA_CHECK(cudaMemcpy(list.indices.data(), indices, pairs * sizeof(std::uint32_t),
                                   cudaMemcpyDeviceToHost));
  }
  if (options.distances) copy_to_host(list.distances, distances, pairs);
  if (options.vectors) copy_to_host(list.vectors, vectors, 3 * pairs);
  if (options.shifts) copy_to_host(list.shifts, shifts, 3 * pairs);
  return list;
}

void DeviceListStorage::set_empty(const ListOptions& list_options) {
  n = 0;
  pairs = 0;
  options = list_options;
  offsets_.resize(1);
  RAYCUT_CUDA_CHECK(cudaMemset(offsets_.data(), 0, sizeof(std::uint64_t)));
  publish();
}

std::uint32_t* DeviceListStorage::prepare_counts(std::size_t targets,
                                                 const ListOptions& list_options) {
  n = targets;
  options = list_options;
  pairs = 0;
  counts_.resize(targets);
  offsets_.resize(targets + 1);
  publish();
  return counts_.data();
}

void DeviceListStorage::scan(cudaStream_t stream) {
  exclusive_sum(counts_.data(), n, offsets_.data(), scan_temp_, stream);
}

std::uint64_t DeviceListStorage::scan_counts(cudaStream_t stream) {
  scan(stream);
  std::uint64_t total = 0;
  read_back(&total, offsets_.data() + n, sizeof total, stream);
  return total;
}

namespace {
__global__ void finish_static_pairs_kernel(const std::uint64_t* total, const int* misfit,
                                           StaticPairs out) {
  const std::uint64_t count = total ? *total : 0;
  const std::uint64_t first = count < out.capacity ? count : out.capacity;
  const std::uint64_t start = blockIdx.x * std::uint64_t{blockDim.x} + threadIdx.x;
  if (start == 0) *out.count = misfit && *misfit != 0 ? *misfit : static_cast<std::int64_t>(count);
  for (std::uint64_t e = first + start; e < out.capacity;
       e += std::uint64_t{gridDim.x} * blockDim.x) {
    out.i[e] = out.j[e] = out.pad_index;
    if (out.shifts) out.shifts[3 * e] = out.shifts[3 * e + 1] = out.shifts[3 * e + 2] = 0;
  }
}
}  // namespace

void finish_static_pairs_on_device(const std::uint64_t* total, const StaticPairs& out,
                                   const int* misfit, cudaStream_t stream) {
  constexpr unsigned threads = 256;
  const std::uint64_t wanted = (out.capacity + threads - 1) / threads;
  const auto blocks =
      static_cast<unsigned>(std::max<std::uint64_t>(1, std::min<std::uint64_t>(wanted, 4096)));
  finish_static_pairs_kernel<<<blocks, threads, 0, stream>>>(total, misfit, out);
  RAYCUT_CUDA_CHECK_LAUNCH();
}

PairCutoffFilter DeviceListStorage::stage_cutoffs(const PairCutoffs* cutoffs, std::size_t n,
                                                  void* stream) {
  // On the stream: a list pass of the previous call that may still read the buffers runs first
  // (the copy from pageable memory is staged at once, so the caller's arrays are free after).
  const auto upload = [stream](auto& buffer, const auto* values, std::size_t count) {
    buffer.resize(std::max<std::size_t>(count, 1));
    if (values && count > 0)
      RAYCUT_CUDA_CHECK(cudaMemcpyAsync(buffer.data(), values, count * sizeof *values,
                                        cudaMemcpyHostToDevice, static_cast<cudaStream_t>(stream)));
    return buffer.data();
  };
  if (!cutoffs || !cutoffs->active()) return {};
  const PairCutoffs& c = *cutoffs;
  const std::size_t entries = std::size_t{c.kinds} * c.kinds;
  return pair_cutoff_filter(c, upload(radii_, c.radii, c.radii ? n : 0),
                            upload(species_, c.species, c.species ? n : 0),
                            upload(table_, c.table, c.table ? entries : 0));
}

ListFill DeviceListStorage::prepare_fill(std::uint64_t entries, const ListFilter& filter) {
  pairs = entries;
  const double per_pair = bytes_per_entry(options);
  const double held = static_cast<double>(indices_.bytes() + distances_.bytes() + vectors_.bytes() +
                                          shifts_.bytes() + rows_.bytes() + columns_.bytes());
  const double need = per_pair * static_cast<double>(entries);
  if (need > held) {
    const std::string what = "a neighbour list of " + std::to_string(entries) + " pairs";
    if (need >= 9.0e18)
      throw Error(ErrorCode::out_of_memory, "not enough device memory for " + what);
    require_device_memory(static_cast<std::size_t>(need - held), what.c_str());
  }
  if (options.coo) {
    rows_.resize(std::max<std::uint64_t>(entries, 1));
    columns_.resize(std::max<std::uint64_t>(entries, 1));
  } else {
    indices_.resize(std::max<std::uint64_t>(entries, 1));
  }
  if (options.distances) distances_.resize(std::max<std::uint64_t>(entries, 1));
  if (options.vectors) vectors_.resize(std::max<std::uint64_t>(3 * entries, 1));
  if (options.shifts) shifts_.resize(std::max<std::uint64_t>(3 * entries, 1));
  publish();
  return {filter,
          offsets_.data(),
          options.coo ? nullptr : indices_.data(),
          options.distances ? distances_.data() : nullptr,
          options.vectors ? vectors_.data() : nullptr,
          options.shifts ? shifts_.data() : nullptr,
          options.coo ? rows_.data() : nullptr,
          options.coo ? columns_.data() : nullptr};
}

void DeviceListStorage::publish() {
  offsets = offsets_.data();
  indices = options.coo ? nullptr : indices_.data();
  distances = options.distances ? distances_.data() : nullptr;
  vectors = options.vectors ? vectors_.data() : nullptr;
  shifts = options.shifts ? shifts_.data() : nullptr;
  rows = options.coo ? rows_.data() : nullptr;
  columns = options.coo ? columns_.data() : nullptr;
}

std::vector<std::uint32_t> DevicePaddedStorage::indices_to_host() const {
  // With its shifts, which the callers copy next (budgeted as the CSR copy is, in to_host).
  require_host_memory(
      (shifts ? 16.0 : 4.0) * static_cast<double>(n) * k,
      "a host copy of a padded neighbour list of " + std::to_string(n) + " x " + std::to_string(k));
  std::vector<std::uint32_t> host;
  copy_to_host(host, indices, n * std::size_t{k});
  return host;
}

std::vector<std::uint32_t> DevicePaddedStorage::counts_to_host() const {
  std::vector<std::uint32_t> host;
  copy_to_host(host, counts, n);
  return host;
}

std::vector<std::int32_t> DevicePaddedStorage::shifts_to_host() const {
  std::vector<std::int32_t> host;
  if (shifts) copy_to_host(host, shifts, 3 * n * std::size_t{k});
  return host;
}

PaddedFill DevicePaddedStorage::prepare(std::size_t targets, std::uint32_t width, bool half,
                                        bool with_shifts, cudaStream_t stream) {
  n = targets;
  k = width;
  const double need = 4.0 * static_cast<double>(targets) *
                      ((with_shifts ? 4.0 : 1.0) * static_cast<double>(width) + 1);
  if (need > static_cast<double>(indices_.bytes() + counts_.bytes())) {
    const std::string what =
        "a padded neighbour list of " + std::to_string(targets) + " x " + std::to_string(width);
    if (need >= 9.0e18)
      throw Error(ErrorCode::out_of_memory, "not enough device memory for " + what);
    require_device_memory(static_cast<std::size_t>(need), what.c_str());
  }
  indices_.resize(targets * std::size_t{width});
  counts_.resize(targets);
  if (with_shifts) shifts_.resize(3 * targets * std::size_t{width});
  indices = indices_.data();
  counts = counts_.data();
  shifts = with_shifts ? shifts_.data() : nullptr;
  overflow_.resize(1);
  RAYCUT_CUDA_CHECK(cudaMemsetAsync(overflow_.data(), 0, sizeof(PaddedOverflow), stream));
  return {{half, {}},      width,          padding,
          indices_.data(), counts_.data(), with_shifts ? shifts_.data() : nullptr,
          overflow_.data()};
}

void DevicePaddedStorage::read_report(cudaStream_t stream) {
  PaddedOverflow overflow;
  read_back(&overflow, overflow_.data(), sizeof overflow, stream);
  report = {overflow.rows, overflow.largest};
}

}  // namespace raycut::detail::cuda
