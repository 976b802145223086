#include "optix/context.hpp"

#include <optix_function_table_definition.h>
#include <optix_stack_size.h>
#include <optix_stubs.h>

#include <algorithm>

#include "optix/optix_check.hpp"

namespace raycut::detail::optix {
namespace {

struct Context {
  OptixDeviceContext handle = nullptr;
  std::string error;
};

const Context& context() {
  static Context ctx = [] {
    Context c;
    try {
      RAYCUT_CUDA_CHECK(cudaFree(nullptr));  // make sure a CUDA context exists
      RAYCUT_OPTIX_CHECK(optixInit());
      OptixDeviceContextOptions options{};
      RAYCUT_OPTIX_CHECK(optixDeviceContextCreate(nullptr, &options, &c.handle));
    } catch (const Error& e) {
      c.handle = nullptr;
      c.error = e.what();
    }
    return c;
  }();
  return ctx;
}

constexpr std::size_t log_capacity = 4096;

}  // namespace

std::string unavailable_reason() {
  return context().error;
}

OptixDeviceContext device_context() {
  const Context& c = context();
  if (!c.handle) throw Error(ErrorCode::unsupported, "OptiX is not available: " + c.error);
  return c.handle;
}

Pipeline::Pipeline(const PipelineSpec& spec) {
  OptixDeviceContext ctx = device_context();
  char log[log_capacity];
  std::size_t log_size = sizeof log;

  OptixModuleCompileOptions module_options{};
  module_options.optLevel = OPTIX_COMPILE_OPTIMIZATION_DEFAULT;
  module_options.debugLevel = OPTIX_COMPILE_DEBUG_LEVEL_NONE;
  OptixPipelineCompileOptions pipeline_options{};
  pipeline_options.traversableGraphFlags = OPTIX_TRAVERSABLE_GRAPH_FLAG_ALLOW_SINGLE_GAS;
  pipeline_options.numPayloadValues = spec.payload_values;
  pipeline_options.numAttributeValues = spec.attribute_values;
  pipeline_options.exceptionFlags = OPTIX_EXCEPTION_FLAG_NONE;
  pipeline_options.pipelineLaunchParamsVariableName = spec.params_name;
  pipeline_options.usesPrimitiveTypeFlags = spec.primitive_types;

  // Stage 1: the module, from the OptiX IR embedded at build time.
  RAYCUT_OPTIX_CHECK_LOG(optixModuleCreate(ctx, &module_options, &pipeline_options,
                                           reinterpret_cast<const char*>(spec.ir), spec.ir_size,
                                           log, &log_size, &module_),
                         log);

  // Stage 2: program groups (raygen, a null miss, one hit group).
  OptixProgramGroupOptions group_options{};
  OptixProgramGroupDesc desc[3] = {};
  desc[0].kind = OPTIX_PROGRAM_GROUP_KIND_RAYGEN;
  desc[0].raygen.module = module_;
  desc[0].raygen.entryFunctionName = spec.programs.raygen;
  desc[1].kind = OPTIX_PROGRAM_GROUP_KIND_MISS;  // null program: the fastest miss
  desc[2].kind = OPTIX_PROGRAM_GROUP_KIND_HITGROUP;
  auto stage = [&](const char* name) { return name && *name ? name : nullptr; };
  if (spec.builtin_intersection != 0) {
    OptixBuiltinISOptions builtin{};
    builtin.builtinISModuleType = static_cast<OptixPrimitiveType>(spec.builtin_intersection);
    RAYCUT_OPTIX_CHECK(optixBuiltinISModuleGet(ctx, &module_options, &pipeline_options, &builtin,
                                               &builtin_module_));
    desc[2].hitgroup.moduleIS = builtin_module_;
  } else if (stage(spec.programs.intersection)) {
    desc[2].hitgroup.moduleIS = module_;
    desc[2].hitgroup.entryFunctionNameIS = spec.programs.intersection;
  }
  if (stage(spec.programs.any_hit)) {
    desc[2].hitgroup.moduleAH = module_;
    desc[2].hitgroup.entryFunctionNameAH = spec.programs.any_hit;
  }
  if (stage(spec.programs.closest_hit)) {
    desc[2].hitgroup.moduleCH = module_;
    desc[2].hitgroup.entryFunctionNameCH = spec.programs.closest_hit;
  }
  OptixProgramGroup groups[3];
  log_size = sizeof log;
  RAYCUT_OPTIX_CHECK_LOG(
      optixProgramGroupCreate(ctx, desc, 3, &group_options, log, &log_size, groups), log);
  raygen_ = groups[0];
  miss_ = groups[1];
  hit_ = groups[2];

  // Stage 3: the pipeline, with a stack sized for one level of tracing.
  OptixPipelineLinkOptions link_options{};
  link_options.maxTraceDepth = 1;
  log_size = sizeof log;
  RAYCUT_OPTIX_CHECK_LOG(optixPipelineCreate(ctx, &pipeline_options, &link_options, groups, 3, log,
                                             &log_size, &pipeline_),
                         log);
  OptixStackSizes sizes{};
  for (OptixProgramGroup g : groups)
    RAYCUT_OPTIX_CHECK(optixUtilAccumulateStackSizes(g, &sizes, pipeline_));
  unsigned from_traversal = 0, from_state = 0, continuation = 0;
  RAYCUT_OPTIX_CHECK(
      optixUtilComputeStackSizes(&sizes, 1, 0, 0, &from_traversal, &from_state, &continuation));
  RAYCUT_OPTIX_CHECK(
      optixPipelineSetStackSize(pipeline_, from_traversal, from_state, continuation, 1));

  // Stage 4: the shader binding table, one header-only record per stage.
  constexpr std::size_t stride = OPTIX_SBT_RECORD_HEADER_SIZE;
  static_assert(stride % OPTIX_SBT_RECORD_ALIGNMENT == 0);
  unsigned char host_records[3 * stride];
  for (int g = 0; g < 3; ++g)
    RAYCUT_OPTIX_CHECK(optixSbtRecordPackHeader(groups[g], host_records + g * stride));
  records_.resize(3 * stride);
  RAYCUT_CUDA_CHECK(
      cudaMemcpy(records_.data(), host_records, sizeof host_records, cudaMemcpyHostToDevice));
  const auto base = reinterpret_cast<CUdeviceptr>(records_.data());
  sbt_.raygenRecord = base;
  sbt_.missRecordBase = base + stride;
  sbt_.missRecordStrideInBytes = stride;
  sbt_.missRecordCount = 1;
  sbt_.hitgroupRecordBase = base + 2 * stride;
  sbt_.hitgroupRecordStrideInBytes = stride;
  sbt_.hitgroupRecordCount = 1;
}

Pipeline::~Pipeline() {
  if (pipeline_) optixPipelineDestroy(pipeline_);
  for (OptixProgramGroup g : {raygen_, miss_, hit_})
    if (g) optixProgramGroupDestroy(g);
  if (module_) optixModuleDestroy(module_);
  if (builtin_module_) optixModuleDestroy(builtin_module_);
}

void Pipeline::launch(const void* params, std::size_t size, unsigned width, cudaStream_t stream) {
  if (width == 0) return;
  params_.resize(size);
  RAYCUT_CUDA_CHECK(cudaMemcpyAsync(params_.data(), params, size, cudaMemcpyHostToDevice, stream));
  RAYCUT_OPTIX_CHECK(optixLaunch(pipeline_, stream, reinterpret_cast<CUdeviceptr>(params_.data()),
                                 size, &sbt_, width, 1, 1));
}

OptixTraversableHandle Accel::build(const OptixBuildInput& input, unsigned build_flags,
                                    cudaStream_t stream) {
  flags_ = build_flags;
  return run(input, OPTIX_BUILD_OPERATION_BUILD, stream);
}

OptixTraversableHandle Accel::refit(const OptixBuildInput& input, cudaStream_t stream) {
  if (!handle_ || !(flags_ & OPTIX_BUILD_FLAG_ALLOW_UPDATE))
    throw Error(ErrorCode::internal, "refit of an acceleration structure built without updates");
  return run(input, OPTIX_BUILD_OPERATION_UPDATE, stream);
}

OptixTraversableHandle Accel::run(const OptixBuildInput& input, OptixBuildOperation operation,
                                  cudaStream_t stream) {
  OptixDeviceContext ctx = device_context();
  OptixAccelBuildOptions options{};
  options.buildFlags = flags_;
  options.operation = operation;
  OptixAccelBufferSizes sizes{};
  RAYCUT_OPTIX_CHECK(optixAccelComputeMemoryUsage(ctx, &options, &input, 1, &sizes));
  const bool update = operation == OPTIX_BUILD_OPERATION_UPDATE;
  const std::size_t temp = update ? sizes.tempUpdateSizeInBytes : sizes.tempSizeInBytes;
  if (!update) {
    const std::size_t need = temp + sizes.outputSizeInBytes, have = temp_.bytes() + output_.bytes();
    if (need > have) cuda::require_device_memory(need - have, "the acceleration structure");
    output_.resize(sizes.outputSizeInBytes);
  }
  temp_.resize(std::max<std::size_t>(temp, 1));
  RAYCUT_OPTIX_CHECK(optixAccelBuild(
      ctx, stream, &options, &input, 1, reinterpret_cast<CUdeviceptr>(temp_.data()), temp,
      reinterpret_cast<CUdeviceptr>(output_.data()), output_.bytes(), &handle_, nullptr, 0));
  return handle_;
}

}  // namespace raycut::detail::optix
