// Double squares (method 3): two face triangles per source (one oversized triangle per square).
#include "geometry/ray_geometry.hpp"
#include "optix/methods.hpp"
#include "optix/ray_method.hpp"

extern const unsigned char raycut_triangles_programs[];
extern const std::size_t raycut_triangles_programs_size;

namespace raycut::detail::optix {
namespace {

// Triangle 2j + f is face f of source j: primitive index / 2 is the source.
__global__ void make_faces(const float* xyz, std::uint32_t n, float cutoff, float margin,
                           float* vertices) {
  const std::uint32_t t = blockIdx.x * blockDim.x + threadIdx.x;
  if (t >= 2 * n) return;
  const std::uint32_t j = t >> 1;
  geometry::face_triangle(xyz[3 * j], xyz[3 * j + 1], xyz[3 * j + 2], static_cast<int>(t & 1),
                          cutoff, margin, vertices + 9 * std::size_t{t});
}

class TrianglesMethod final : public RayTracingMethod {
 public:
  TrianglesMethod()
      : RayTracingMethod(false, {raycut_triangles_programs,
                                 raycut_triangles_programs_size,
                                 {"__raygen__triangles", "", "__anyhit__triangles", ""},
                                 3,
                                 2,
                                 static_cast<unsigned>(OPTIX_PRIMITIVE_TYPE_FLAGS_TRIANGLE),
                                 "params"}) {}

 private:
  const char* name() const override { return "optix-triangles"; }
  geometry::Shape shape() const override { return geometry::Shape::triangles; }
  OptixBuildInput primitives(const float* xyz, std::uint32_t n, float cutoff,
                             float margin) override {
    vertices_.resize(18 * std::size_t{n});
    make_faces<<<blocks_for(2 * std::size_t{n}), block_size>>>(xyz, n, cutoff, margin,
                                                               vertices_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    vertex_pointer_ = reinterpret_cast<CUdeviceptr>(vertices_.data());
    OptixBuildInput input{};
    input.type = OPTIX_BUILD_INPUT_TYPE_TRIANGLES;
    input.triangleArray.vertexFormat = OPTIX_VERTEX_FORMAT_FLOAT3;
    input.triangleArray.vertexStrideInBytes = 3 * sizeof(float);
    input.triangleArray.numVertices = 6 * n;
    input.triangleArray.vertexBuffers = &vertex_pointer_;
    input.triangleArray.flags = &flags_;
    input.triangleArray.numSbtRecords = 1;
    return input;
  }

  cuda::DeviceBuffer<float> vertices_;
  CUdeviceptr vertex_pointer_ = 0;
  const unsigned flags_ = OPTIX_GEOMETRY_FLAG_REQUIRE_SINGLE_ANYHIT_CALL;
};

}  // namespace

std::unique_ptr<Method> make_triangles() {
  return std::make_unique<TrianglesMethod>();
}

}  // namespace raycut::detail::optix
