// The expansion of core/images.hpp on the GPU: positions in device memory, points in device
// memory, the same layout as the host's (core/image_frame.hpp runs on both). Host-only header;
// defined in images.cu, compiled in only with CUDA.
#pragma once

#include <memory>

#include "core/images.hpp"

namespace raycut::detail::cuda {

// Queued on `stream` (a cudaStream_t); reads the number of images back once, to size the points.
std::shared_ptr<ImagePoints> expand_on_device(const ImagePlan& plan, const float* sources,
                                              const float* queries, void* stream);

}  // namespace raycut::detail::cuda
