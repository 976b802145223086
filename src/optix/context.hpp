// The one OptiX wrapper every ray-tracing method uses, in named stages: the device context
// (once per process), a pipeline from an embedded OptiX IR module (module, program groups,
// pipeline, stack size, SBT), and the acceleration structure build for one build input.
#pragma once

#include <cuda_runtime.h>
#include <optix.h>

#include <cstddef>
#include <string>

#include "cuda/device_buffer.cuh"

namespace raycut::detail::optix {

// The process-wide OptiX device context on the current CUDA device (created on first use).
OptixDeviceContext device_context();

// Empty when OptiX can be initialised here; otherwise why not (no driver support, ...).
std::string unavailable_reason();

// What a method's programs are: entry names in one module; "" for a stage it does not use.
struct ProgramNames {
  const char* raygen;
  const char* intersection;
  const char* any_hit;
  const char* closest_hit;
};

struct PipelineSpec {
  const unsigned char* ir;  // OptiX IR, embedded at build time
  std::size_t ir_size;
  ProgramNames programs;
  int payload_values;
  int attribute_values;
  unsigned primitive_types;  // OptixPrimitiveTypeFlags
  const char* params_name;   // the __constant__ launch-parameter variable
  // A built-in intersection (e.g. OPTIX_PRIMITIVE_TYPE_SPHERE), or 0 for triangles / custom.
  unsigned builtin_intersection = 0;
};

// A ready-to-launch pipeline with a one-record-per-stage SBT (no per-record data).
class Pipeline {
 public:
  explicit Pipeline(const PipelineSpec& spec);
  ~Pipeline();
  Pipeline(const Pipeline&) = delete;
  Pipeline& operator=(const Pipeline&) = delete;

  // Launches width x 1 x 1 raygen threads with `params` (size bytes) copied to the device first.
  void launch(const void* params, std::size_t size, unsigned width, cudaStream_t stream = nullptr);

 private:
  OptixModule module_ = nullptr, builtin_module_ = nullptr;
  OptixProgramGroup raygen_ = nullptr, miss_ = nullptr, hit_ = nullptr;
  OptixPipeline pipeline_ = nullptr;
  cuda::DeviceBuffer<unsigned char> records_;  // raygen, miss, hit: one header each
  cuda::DeviceBuffer<unsigned char> params_;
  OptixShaderBindingTable sbt_{};
};

// A geometry acceleration structure over one build input, rebuilt from scratch by build() (as in
// the paper) or refitted in place by refit() (OptiX update: same topology, new bounds; the last
// build must have had OPTIX_BUILD_FLAG_ALLOW_UPDATE). Buffers are kept and only grow.
class Accel {
 public:
  OptixTraversableHandle build(const OptixBuildInput& input, unsigned build_flags,
                               cudaStream_t stream = nullptr);
  OptixTraversableHandle refit(const OptixBuildInput& input, cudaStream_t stream = nullptr);
  std::size_t bytes() const { return output_.bytes() + temp_.bytes(); }

 private:
  OptixTraversableHandle run(const OptixBuildInput& input, OptixBuildOperation operation,
                             cudaStream_t stream);

  unsigned flags_ = 0;
  OptixTraversableHandle handle_ = 0;
  cuda::DeviceBuffer<unsigned char> temp_, output_;
};

}  // namespace raycut::detail::optix
