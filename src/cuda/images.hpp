// The expansion of core/images.hpp on the GPU: positions in device memory, points in device
// memory, the same layout as the host's (core/image_frame.hpp runs on both). Host-only header;
// defined in images.cu, compiled in only with CUDA.
#pragma once

#include <memory>

#include "core/images.hpp"

namespace raycut::detail::cuda {

// expand() queues its work on `stream` and reads the number of images back once, to size the
// points.
std::unique_ptr<ImagePoints> make_device_image_points();

}  // namespace raycut::detail::cuda
