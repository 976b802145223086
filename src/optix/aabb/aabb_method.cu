// Method 4 of the paper: custom AABBs with zero-length rays, unsorted or spatially sorted
// (Morton order of the cells of width C, so that neighbouring rays and their boxes are close
// in memory). See programs.cu for why the pair work is in any-hit.
#include <cub/device/device_radix_sort.cuh>

#include <cmath>
#include <memory>

#include "core/cell_grid.hpp"
#include "cuda/grid_common.cuh"
#include "optix/aabb/params.hpp"
#include "optix/context.hpp"
#include "optix/methods.hpp"

extern const unsigned char raycut_aabb_programs[];
extern const std::size_t raycut_aabb_programs_size;

namespace raycut::detail::optix {
namespace {

// Spreads the low 21 bits of v to every third bit.
__host__ __device__ std::uint64_t spread_bits(std::uint64_t v) {
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

__global__ void gather_positions(const float* xyz, const std::uint32_t* ids, std::uint32_t n,
                                 float* sorted) {
  const std::uint32_t s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= n) return;
  const std::uint32_t i = ids[s];
  sorted[3 * s] = xyz[3 * i];
  sorted[3 * s + 1] = xyz[3 * i + 1];
  sorted[3 * s + 2] = xyz[3 * i + 2];
}

// Boxes of half-width C, widened by a relative 2^-20 of the coordinates' magnitude so that float
// rounding of p +- C can never shut out a source the predicate calls in range.
__global__ void make_boxes(const float* xyz, std::uint32_t n, float cutoff, OptixAabb* boxes) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const float x = xyz[3 * i], y = xyz[3 * i + 1], z = xyz[3 * i + 2];
  const float m = fmaxf(fmaxf(fabsf(x), fabsf(y)), fmaxf(fabsf(z), cutoff));
  const float h = cutoff + m * 0x1p-20f;
  boxes[i] = OptixAabb{x - h, y - h, z - h, x + h, y + h, z + h};
}

constexpr unsigned block = 256;
unsigned blocks(std::size_t n) {
  return static_cast<unsigned>((n + block - 1) / block);
}

class AabbMethod final : public Method {
 public:
  explicit AabbMethod(bool sorted)
      : sorted_(sorted),
        pipeline_({raycut_aabb_programs,
                   raycut_aabb_programs_size,
                   {"__raygen__aabb", "__intersection__aabb", "__anyhit__aabb", ""},
                   2,
                   4,
                   OPTIX_PRIMITIVE_TYPE_FLAGS_CUSTOM,
                   "params"}) {}

  MemorySpace space() const override { return MemorySpace::device; }

  void build(const float* xyz, std::size_t n, float cutoff) override {
    if (n > 0xffffffffu)
      throw Error(ErrorCode::invalid_argument, "custom-AABB methods take at most 2^32-1 particles");
    n_ = static_cast<std::uint32_t>(n);
    cutoff_ = cutoff;
    build_timer_.start();
    xyz_.resize(3 * n);
    if (sorted_) {
      sort_spatially(xyz);
    } else {
      RAYCUT_CUDA_CHECK(
          cudaMemcpyAsync(xyz_.data(), xyz, 3 * n * sizeof(float), cudaMemcpyDeviceToDevice));
    }
    boxes_.resize(n);
    make_boxes<<<blocks(n), block>>>(xyz_.data(), n_, cutoff, boxes_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();

    const CUdeviceptr box_ptr = reinterpret_cast<CUdeviceptr>(boxes_.data());
    const unsigned flags = OPTIX_GEOMETRY_FLAG_REQUIRE_SINGLE_ANYHIT_CALL;
    OptixBuildInput input{};
    input.type = OPTIX_BUILD_INPUT_TYPE_CUSTOM_PRIMITIVES;
    input.customPrimitiveArray.aabbBuffers = &box_ptr;
    input.customPrimitiveArray.numPrimitives = n_;
    input.customPrimitiveArray.flags = &flags;
    input.customPrimitiveArray.numSbtRecords = 1;
    handle_ = accel_.build(input, OPTIX_BUILD_FLAG_PREFER_FAST_TRACE);
    build_timer_.stop();
  }

  void compute(Kernel kernel, const KernelOptions& options) override {
    AabbParams p = base_params();
    p.mode = kernel == Kernel::count ? AabbMode::count
             : kernel == Kernel::lj  ? AabbMode::lj
                                     : AabbMode::smooth;
    p.lj_four_epsilon = 4.0f * options.lj_epsilon;
    p.lj_sigma_squared = options.lj_sigma * options.lj_sigma;
    p.out = results_.prepare(kernel, n_);
    compute_timer_.start();
    pipeline_.launch(&p, sizeof p, n_);
    compute_timer_.stop();
  }

  Results results() const override { return results_.to_host(); }

  NeighbourList neighbours() override {
    return cuda::build_neighbour_list(
        n_,
        [&](std::uint32_t* counts) {
          AabbParams p = base_params();
          p.mode = AabbMode::list_count;
          p.list_counts = counts;
          pipeline_.launch(&p, sizeof p, n_);
        },
        [&](const std::uint64_t* offsets, std::uint32_t* indices) {
          AabbParams p = base_params();
          p.mode = AabbMode::list_fill;
          p.list_offsets = offsets;
          p.list_indices = indices;
          pipeline_.launch(&p, sizeof p, n_);
        });
  }

  void synchronize() override { RAYCUT_CUDA_CHECK(cudaDeviceSynchronize()); }
  double device_build_ms() const override { return build_timer_.elapsed_ms(); }
  double device_compute_ms() const override { return compute_timer_.elapsed_ms(); }

 private:
  AabbParams base_params() const {
    AabbParams p{};
    p.handle = handle_;
    p.xyz = xyz_.data();
    p.origin = sorted_ ? ids_.data() : nullptr;
    p.n = n_;
    p.cutoff_squared = squared_cutoff(cutoff_);
    return p;
  }

  // Morton order of cells of width C (cub radix sort of 63-bit keys), counted in the build.
  void sort_spatially(const float* xyz) {
    float lo[3], hi[3];
    bbox_.compute(xyz, n_, lo, hi);
    const CellGrid grid = make_cell_grid(lo, hi, cutoff_);
    keys_.resize(2 * std::size_t{n_});
    ids_.resize(2 * std::size_t{n_});
    morton_keys<<<blocks(n_), block>>>(xyz, n_, grid, keys_.data(), ids_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    cub::DoubleBuffer<std::uint64_t> keys(keys_.data(), keys_.data() + n_);
    cub::DoubleBuffer<std::uint32_t> ids(ids_.data(), ids_.data() + n_);
    std::size_t temp_bytes = 0;
    RAYCUT_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(nullptr, temp_bytes, keys, ids, n_, 0, 63));
    sort_temp_.resize(temp_bytes);
    RAYCUT_CUDA_CHECK(
        cub::DeviceRadixSort::SortPairs(sort_temp_.data(), temp_bytes, keys, ids, n_, 0, 63));
    if (ids.Current() != ids_.data())  // keep the sorted ids at the front of the buffer
      RAYCUT_CUDA_CHECK(cudaMemcpyAsync(ids_.data(), ids.Current(), n_ * sizeof(std::uint32_t),
                                        cudaMemcpyDeviceToDevice));
    gather_positions<<<blocks(n_), block>>>(xyz, ids_.data(), n_, xyz_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
  }

  bool sorted_;
  Pipeline pipeline_;
  Accel accel_;
  OptixTraversableHandle handle_ = 0;
  std::uint32_t n_ = 0;
  float cutoff_ = 0;
  cuda::DeviceBuffer<float> xyz_;
  cuda::DeviceBuffer<OptixAabb> boxes_;
  cuda::DeviceBuffer<std::uint64_t> keys_;
  cuda::DeviceBuffer<std::uint32_t> ids_;
  cuda::DeviceBuffer<unsigned char> sort_temp_;
  cuda::BoundingBox bbox_;
  cuda::DeviceResults results_;
  cuda::EventTimer build_timer_, compute_timer_;
};

}  // namespace

std::unique_ptr<Method> make_aabb(bool sorted) {
  return std::make_unique<AabbMethod>(sorted);
}

}  // namespace raycut::detail::optix
