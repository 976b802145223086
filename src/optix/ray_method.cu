#include "optix/ray_method.hpp"

#include <cub/device/device_radix_sort.cuh>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>

#include "geometry/ray_geometry.hpp"
#include "raycut/detail/cell_grid.hpp"

namespace raycut::detail::optix {
namespace {

// Spreads the low 21 bits of v to every third bit (Morton interleave).
__device__ std::uint64_t spread_bits(std::uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffULL;
  v = (v | v << 16) & 0x1f0000ff0000ffULL;
  v = (v | v << 8) & 0x100f00f00f00f00fULL;
  v = (v | v << 4) & 0x10c30c30c30c30c3ULL;
  v = (v | v << 2) & 0x1249249249249249ULL;
  return v;
}

__global__ void morton_keys(const float* xyz, std::uint32_t n, CellGrid grid, std::uint64_t* keys,
                            std::uint32_t* ids) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const float x = xyz[3 * i], y = xyz[3 * i + 1], z = xyz[3 * i + 2];
  keys[i] = spread_bits(grid.coord(x, 0)) | spread_bits(grid.coord(y, 1)) << 1 |
            spread_bits(grid.coord(z, 2)) << 2;
  ids[i] = i;
}

// Positions in the local frame: (x - shift) * scale, exact (geometry::exact_shift, scale a power
// of two putting the cutoff in [1, 2)), so every pair vector the programs compute, times
// 1 / scale, is the caller's d = x_j - x_i bit for bit (barring subnormals, below 2^-126 C),
// whatever the magnitude of the coordinates and of the cutoff: OptiX's traversal is not exact
// far from unit scale (docs/methods.md, "Valid domain of each ray-tracing method").
// ids: slot -> caller's index (the Morton order), or null.
__global__ void to_local_frame(const float* xyz, const std::uint32_t* ids, std::uint32_t n,
                               float3 shift, float scale, float* local) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= n) return;
  const std::uint32_t i = ids ? ids[s] : s;
  local[3 * s] = (xyz[3 * i] - shift.x) * scale;
  local[3 * s + 1] = (xyz[3 * i + 1] - shift.y) * scale;
  local[3 * s + 2] = (xyz[3 * i + 2] - shift.z) * scale;
}

// Squared displacements are >= 0, so their float bits order like unsigned integers.
__global__ void max_squared_displacement(const float* now, const float* then, std::size_t n,
                                         unsigned* result) {
  const std::size_t i = blockIdx.x * std::size_t{blockDim.x} + threadIdx.x;
  if (i >= n) return;
  const float dx = now[3 * i] - then[3 * i], dy = now[3 * i + 1] - then[3 * i + 1],
              dz = now[3 * i + 2] - then[3 * i + 2];
  atomicMax(result, __float_as_uint(dx * dx + dy * dy + dz * dz));
}

}  // namespace

RayTracingMethod::RayTracingMethod(bool sorted, const PipelineSpec& programs)
    : sorted_(sorted), pipeline_(programs) {}

void RayTracingMethod::build(const float* xyz, std::size_t n, float cutoff) {
  if (n > 0x7fffffffu)
    throw Error(ErrorCode::invalid_argument,
                "ray-tracing methods take at most 2^31-1 particles, got " + std::to_string(n));
  build_timer_.start();
  // The local frame, the valid domain and the margin need the box; the sort needs it too.
  float lo[3], hi[3], shift[3];
  bbox_.compute(xyz, n, lo, hi);
  for (int a = 0; a < 3; ++a) shift[a] = geometry::exact_shift(lo[a], hi[a]);
  // The skin widens the magnitude so refitted positions stay covered (and in the domain).
  const double magnitude = geometry::local_magnitude(lo, hi, shift) + policy_.skin;
  check_domain(magnitude, cutoff);  // before any launch of the method; the last build stays
  n_ = static_cast<std::uint32_t>(n);
  cutoff_ = cutoff;
  std::copy(shift, shift + 3, shift_);
  scale_ = std::ldexp(1.0f, -std::ilogb(cutoff));  // the local cutoff in [1, 2)
  margin_ = geometry::margin(cutoff * scale_, static_cast<float>(magnitude * scale_));

  xyz_.resize(3 * n);
  if (sorted_) {
    const CellGrid grid = make_cell_grid(lo, hi, cutoff);
    keys_.resize(2 * n);
    ids_.resize(2 * n);
    morton_keys<<<blocks_for(n), block_size>>>(xyz, n_, grid, keys_.data(), ids_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    cub::DoubleBuffer<std::uint64_t> keys(keys_.data(), keys_.data() + n);
    cub::DoubleBuffer<std::uint32_t> ids(ids_.data(), ids_.data() + n);
    std::size_t temp_bytes = 0;
    RAYCUT_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, keys, ids, n_, 0, 63));
    sort_temp_.resize(temp_bytes);
    RAYCUT_CUDA_CHECK(
        cub::DeviceRadixSort::SortPairs(sort_temp_.data(), temp_bytes, keys, ids, n_, 0, 63));
    if (ids.Current() != ids_.data())  // the sorted ids live at the front of the buffer
      RAYCUT_CUDA_CHECK(cudaMemcpyAsync(ids_.data(), ids.Current(), n * sizeof(std::uint32_t),
                                        cudaMemcpyDeviceToDevice));
  }
  arrange(xyz);
  const bool refits = policy_.skin > 0;
  if (refits) {
    built_xyz_.resize(3 * n);
    RAYCUT_CUDA_CHECK(
        cudaMemcpyAsync(built_xyz_.data(), xyz, 3 * n * sizeof(float), cudaMemcpyDeviceToDevice));
  }
  const OptixBuildInput input = primitives(xyz_.data(), n_, cutoff * scale_, margin_);
  handle_ = accel_.build(
      input, OPTIX_BUILD_FLAG_PREFER_FAST_TRACE | (refits ? OPTIX_BUILD_FLAG_ALLOW_UPDATE : 0));
  build_timer_.stop();
}

void RayTracingMethod::check_domain(double magnitude, float cutoff) const {
  const double cutoffs = magnitude / cutoff, bound = geometry::max_scene_cutoffs(shape());
  if (cutoffs <= bound) return;
  char text[400];
  std::snprintf(
      text, sizeof text,
      "%s: the scene extends %.3g cutoffs from its local origin (largest |x - origin| / C, "
      "skin included), beyond the %.0f this method supports: its float ray-tracing "
      "geometry cannot resolve the cutoff at that extent (docs/methods.md, \"Valid "
      "domain of each ray-tracing method\"). Use the grid method (\"grid\", or "
      "\"cell-list\" on the CPU), exact at any extent",
      name(), cutoffs, bound);
  throw Error(ErrorCode::unsupported, text);
}

void RayTracingMethod::arrange(const float* xyz) {
  to_local_frame<<<blocks_for(n_), block_size>>>(xyz, sorted_ ? ids_.data() : nullptr, n_,
                                                 make_float3(shift_[0], shift_[1], shift_[2]),
                                                 scale_, xyz_.data());
  RAYCUT_CUDA_CHECK_LAUNCH();
}

float RayTracingMethod::max_displacement(const float* xyz) {
  displacement_.resize(1);
  RAYCUT_CUDA_CHECK(cudaMemsetAsync(displacement_.data(), 0, sizeof(unsigned)));
  max_squared_displacement<<<blocks_for(n_), block_size>>>(xyz, built_xyz_.data(), n_,
                                                           displacement_.data());
  RAYCUT_CUDA_CHECK_LAUNCH();
  unsigned bits = 0;
  RAYCUT_CUDA_CHECK(cudaMemcpy(&bits, displacement_.data(), sizeof bits, cudaMemcpyDeviceToHost));
  float squared;
  std::memcpy(&squared, &bits, sizeof squared);
  return std::sqrt(squared);
}

bool RayTracingMethod::shift_stays_exact(const float* xyz) {
  if (shift_[0] == 0 && shift_[1] == 0 && shift_[2] == 0) return true;
  float lo[3], hi[3];
  bbox_.compute(xyz, n_, lo, hi);
  for (int a = 0; a < 3; ++a)
    if (!geometry::shift_is_exact(lo[a], hi[a], shift_[a])) return false;
  return true;
}

bool RayTracingMethod::update(const float* xyz, std::size_t n, float cutoff) {
  // Refit keeps the tree of the last build and moves its boxes with the particles: exact, but
  // the tree degrades as particles wander, hence the rebuild beyond half the skin. The margin of
  // the last build stays (it covers round-off up to the coordinates seen then, plus the skin).
  const bool can_refit = policy_.skin > 0 && n == n_ && cutoff == cutoff_ && handle_ != 0 &&
                         built_xyz_.size() == 3 * n;
  if (!can_refit || max_displacement(xyz) > 0.5f * policy_.skin || !shift_stays_exact(xyz)) {
    build(xyz, n, cutoff);
    return false;
  }
  build_timer_.start();
  arrange(xyz);
  const OptixBuildInput input = primitives(xyz_.data(), n_, cutoff_ * scale_, margin_);
  handle_ = accel_.refit(input);
  build_timer_.stop();
  return true;
}

LaunchParams RayTracingMethod::base_params() const {
  LaunchParams p{};
  p.handle = handle_;
  p.xyz = xyz_.data();
  p.origin = sorted_ ? ids_.data() : nullptr;
  p.n = n_;
  p.cutoff = cutoff_ * scale_;
  p.cutoff_squared = squared_cutoff(cutoff_);
  p.margin = margin_;
  p.inverse_scale = 1.0f / scale_;
  return p;
}

template <class F>
void RayTracingMethod::launch(const F& f) {
  LaunchParams p = base_params();
  set_functor(p, f);
  pipeline_.launch(&p, sizeof p, n_, stream_);
}

void RayTracingMethod::compute(Kernel kernel, const KernelOptions& options) {
  timed_compute(kernel, n_, [&](const KernelOutputs& out) {
    with_kernel(kernel, options, squared_cutoff(cutoff_), out, [&](const auto& f) { launch(f); });
  });
}

void RayTracingMethod::neighbours(ListStorage& list, const ListOptions& options) {
  device_neighbours(list, n_, options, nullptr, [&](const auto& f) { launch(f); });
}

void RayTracingMethod::padded_neighbours(PaddedStorage& list, std::uint32_t k, bool half,
                                         bool shifts) {
  device_padded(list, n_, k, half, shifts, [&](const auto& f) { launch(f); });
}

void RayTracingMethod::static_neighbours(const StaticPairs& out, const ListOptions& options,
                                         std::size_t n) {
  device_static_neighbours(out, options, n, nullptr, [&](const auto& f) { launch(f); });
}

}  // namespace raycut::detail::optix
