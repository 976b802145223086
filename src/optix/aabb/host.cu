// Custom AABBs (method 4): one box of half-width C + e per source.
#include "geometry/ray_geometry.hpp"
#include "optix/methods.hpp"
#include "optix/ray_method.hpp"

extern const unsigned char raycut_aabb_programs[];
extern const std::size_t raycut_aabb_programs_size;

namespace raycut::detail::optix {
namespace {

__global__ void make_boxes(const float* xyz, std::uint32_t n, float half, OptixAabb* boxes) {
  const std::uint32_t i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  const float x = xyz[3 * i], y = xyz[3 * i + 1], z = xyz[3 * i + 2];
  boxes[i] = OptixAabb{x - half, y - half, z - half, x + half, y + half, z + half};
}

class AabbMethod final : public RayTracingMethod {
 public:
  AabbMethod(bool sorted, bool fused)
      : RayTracingMethod(sorted, {raycut_aabb_programs,
                                  raycut_aabb_programs_size,
                                  {"__raygen__aabb",
                                   fused ? "__intersection__aabb_fused" : "__intersection__aabb",
                                   fused ? "" : "__anyhit__aabb", ""},
                                  2,
                                  0,
                                  OPTIX_PRIMITIVE_TYPE_FLAGS_CUSTOM,
                                  "params"}),
        name_(fused    ? "optix-aabb-fused"
              : sorted ? "optix-aabb-sorted"
                       : "optix-aabb") {}

 private:
  const char* name() const override { return name_; }
  geometry::Shape shape() const override { return geometry::Shape::aabb; }
  OptixBuildInput primitives(const float* xyz, std::uint32_t n, float cutoff,
                             float margin) override {
    boxes_.resize(n);
    make_boxes<<<blocks_for(n), block_size>>>(xyz, n, geometry::aabb_half_width(cutoff, margin),
                                              boxes_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    box_pointer_ = reinterpret_cast<CUdeviceptr>(boxes_.data());
    OptixBuildInput input{};
    input.type = OPTIX_BUILD_INPUT_TYPE_CUSTOM_PRIMITIVES;
    input.customPrimitiveArray.aabbBuffers = &box_pointer_;
    input.customPrimitiveArray.numPrimitives = n;
    input.customPrimitiveArray.flags = &flags_;
    input.customPrimitiveArray.numSbtRecords = 1;
    return input;
  }

  const char* name_;
  cuda::DeviceBuffer<OptixAabb> boxes_;
  CUdeviceptr box_pointer_ = 0;
  const unsigned flags_ = OPTIX_GEOMETRY_FLAG_REQUIRE_SINGLE_ANYHIT_CALL;
};

}  // namespace

std::unique_ptr<Method> make_aabb(bool sorted, bool fused) {
  return std::make_unique<AabbMethod>(sorted, fused);
}

}  // namespace raycut::detail::optix
