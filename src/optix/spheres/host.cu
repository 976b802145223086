// Built-in spheres (method 2): one sphere of radius C sqrt(2/3) + e per source.
#include "geometry/ray_geometry.hpp"
#include "optix/methods.hpp"
#include "optix/ray_method.hpp"

extern const unsigned char raycut_spheres_programs[];
extern const std::size_t raycut_spheres_programs_size;

namespace raycut::detail::optix {
namespace {

class SpheresMethod final : public RayTracingMethod {
 public:
  SpheresMethod()
      : RayTracingMethod(false, {raycut_spheres_programs,
                                 raycut_spheres_programs_size,
                                 {"__raygen__spheres", "", "__anyhit__spheres", ""},
                                 3,
                                 0,
                                 OPTIX_PRIMITIVE_TYPE_FLAGS_SPHERE,
                                 "params",
                                 OPTIX_PRIMITIVE_TYPE_SPHERE}) {}

 private:
  const char* name() const override { return "optix-spheres"; }
  geometry::Shape shape() const override { return geometry::Shape::spheres; }
  OptixBuildInput primitives(const float* xyz, std::uint32_t n, float cutoff,
                             float margin) override {
    radius_ = geometry::sphere_rays(cutoff, margin).radius;
    centres_ = reinterpret_cast<CUdeviceptr>(xyz);  // the positions are the centres
    radius_buffer_.resize(1);
    RAYCUT_CUDA_CHECK(
        cudaMemcpyAsync(radius_buffer_.data(), &radius_, sizeof radius_, cudaMemcpyHostToDevice));
    radius_pointer_ = reinterpret_cast<CUdeviceptr>(radius_buffer_.data());
    OptixBuildInput input{};
    input.type = OPTIX_BUILD_INPUT_TYPE_SPHERES;
    input.sphereArray.vertexBuffers = &centres_;
    input.sphereArray.vertexStrideInBytes = 3 * sizeof(float);
    input.sphereArray.numVertices = n;
    input.sphereArray.radiusBuffers = &radius_pointer_;
    input.sphereArray.singleRadius = 1;
    input.sphereArray.flags = &flags_;
    input.sphereArray.numSbtRecords = 1;
    return input;
  }

  float radius_ = 0;
  cuda::DeviceBuffer<float> radius_buffer_;
  CUdeviceptr centres_ = 0, radius_pointer_ = 0;
  const unsigned flags_ = OPTIX_GEOMETRY_FLAG_REQUIRE_SINGLE_ANYHIT_CALL;
};

}  // namespace

std::unique_ptr<Method> make_spheres() {
  return std::make_unique<SpheresMethod>();
}

}  // namespace raycut::detail::optix
