// What the engine asks of the CUDA backend, without depending on it: memory moves between host
// and device, checks of device positions, the device form of the points with images. The backend
// provides them (src/cuda/device_services.cpp); the composition root (src/backends/registry.cpp)
// hands them to core, null when raycut is built without CUDA.
#pragma once

#include <cstddef>
#include <memory>
#include <string>

#include "core/images.hpp"

namespace raycut::detail {

// Device memory that frees itself (with the backend's function).
struct DeviceDeleter {
  void (*free)(void*) = nullptr;
  void operator()(void* p) const noexcept {
    if (free) free(p);
  }
};
using DeviceBytes = std::unique_ptr<void, DeviceDeleter>;

class DeviceServices {
 public:
  virtual ~DeviceServices() = default;
  // Whether a CUDA device is usable in this process.
  virtual bool available() const = 0;
  // The index of the first particle of (n, 3) device positions with a non-finite coordinate, or
  // n; on `stream`.
  virtual std::size_t first_non_finite(const float* device_xyz, std::size_t n,
                                       void* stream) const = 0;
  virtual void download(void* host, const void* device, std::size_t bytes) const = 0;
  virtual DeviceBytes upload(const void* host, std::size_t bytes) const = 0;
  // Frees device memory released from a DeviceBytes of these services.
  virtual void free(void* device) const = 0;
  // A device copy of device memory, on `stream`.
  virtual DeviceBytes copy_on_device(const void* device, std::size_t bytes, void* stream) const = 0;
  // Whether some particle of `now` is more than `distance` from where `then` has it, or has a
  // non-finite coordinate (both (n, 3) on the device).
  virtual bool moved_beyond(const float* now, const float* then, std::size_t n, float distance,
                            void* stream) const = 0;
  // Points with images expanded on the device (core/images.hpp).
  virtual std::unique_ptr<ImagePoints> make_image_points() const = 0;
  virtual std::string device_name() const = 0;
  virtual std::string runtime_version() const = 0;
};

// The CUDA backend's services, or null when raycut is built without CUDA (defined by the
// composition root, src/backends/registry.cpp).
const DeviceServices* device_services();
// The OptiX headers' version raycut was built with ("9.0.0"), or empty.
std::string optix_headers_version();

}  // namespace raycut::detail
