// One way to check CUDA calls: throw raycut::Error(backend) with the call, file and line.
#pragma once

#include <cuda_runtime.h>

#include <string>

#include "raycut/error.hpp"

namespace raycut::detail::cuda {

[[noreturn]] inline void throw_cuda(cudaError_t status, const char* call, const char* file,
                                    int line) {
  const ErrorCode code =
      status == cudaErrorMemoryAllocation ? ErrorCode::out_of_memory : ErrorCode::backend;
  throw Error(code, std::string("CUDA error '") + cudaGetErrorString(status) + "' in " + call +
                        " at " + file + ":" + std::to_string(line));
}

}  // namespace raycut::detail::cuda

#define RAYCUT_CUDA_CHECK(call)                                                      \
  do {                                                                               \
    const cudaError_t raycut_status_ = (call);                                       \
    if (raycut_status_ != cudaSuccess)                                               \
      ::raycut::detail::cuda::throw_cuda(raycut_status_, #call, __FILE__, __LINE__); \
  } while (0)

// After a kernel launch: launch-configuration errors surface here, not at the next sync.
#define RAYCUT_CUDA_CHECK_LAUNCH() RAYCUT_CUDA_CHECK(cudaGetLastError())
