// Checking OptiX calls: throw raycut::Error(backend) with the call, the result name, the file and
// line, and the compile/link log when there is one.
#pragma once

#include <optix.h>

#include <string>

#include "raycut/error.hpp"

namespace raycut::detail::optix {

[[noreturn]] inline void throw_optix(OptixResult result, const char* call, const char* file,
                                     int line, const char* log = nullptr) {
  std::string message = std::string("OptiX error ") + optixGetErrorName(result) + " (" +
                        optixGetErrorString(result) + ") in " + call + " at " + file + ":" +
                        std::to_string(line);
  if (log && *log) message += "\nlog:\n" + std::string(log);
  throw Error(result == OPTIX_ERROR_HOST_OUT_OF_MEMORY || result == OPTIX_ERROR_DEVICE_OUT_OF_MEMORY
                  ? ErrorCode::out_of_memory
                  : ErrorCode::backend,
              message);
}

}  // namespace raycut::detail::optix

#define RAYCUT_OPTIX_CHECK(call)                                                       \
  do {                                                                                 \
    const OptixResult raycut_result_ = (call);                                         \
    if (raycut_result_ != OPTIX_SUCCESS)                                               \
      ::raycut::detail::optix::throw_optix(raycut_result_, #call, __FILE__, __LINE__); \
  } while (0)

// For calls that fill `log`: the log goes into the error.
#define RAYCUT_OPTIX_CHECK_LOG(call, log)                                                   \
  do {                                                                                      \
    const OptixResult raycut_result_ = (call);                                              \
    if (raycut_result_ != OPTIX_SUCCESS)                                                    \
      ::raycut::detail::optix::throw_optix(raycut_result_, #call, __FILE__, __LINE__, log); \
  } while (0)
