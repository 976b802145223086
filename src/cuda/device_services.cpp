// The engine's device services (core/device_services.hpp) on the CUDA runtime: each forwards to
// the function of cuda/runtime.hpp or cuda/images.hpp that does the work.
#include <memory>
#include <string>

#include "core/device_services.hpp"
#include "cuda/images.hpp"
#include "cuda/methods.hpp"
#include "cuda/runtime.hpp"

namespace raycut::detail::cuda {
namespace {

void free_device(void* p) {
  DeviceFree{}(p);
}

DeviceBytes owned(DeviceMemory memory) {
  return DeviceBytes(memory.release(), DeviceDeleter{free_device});
}

class CudaServices final : public DeviceServices {
 public:
  bool available() const override { return device_available(); }
  std::size_t first_non_finite(const float* device_xyz, std::size_t n,
                               void* stream) const override {
    return cuda::first_non_finite(device_xyz, n, stream);
  }
  void download(void* host, const void* device, std::size_t bytes) const override {
    cuda::download(host, device, bytes);
  }
  DeviceBytes upload(const void* host, std::size_t bytes) const override {
    return owned(cuda::upload(host, bytes));
  }
  void free(void* device) const override { free_device(device); }
  DeviceBytes copy_on_device(const void* device, std::size_t bytes, void* stream) const override {
    return owned(cuda::copy_on_device(device, bytes, stream));
  }
  bool moved_beyond(const float* now, const float* then, std::size_t n, float distance,
                    void* stream) const override {
    return cuda::moved_beyond(now, then, n, distance, stream);
  }
  std::unique_ptr<ImagePoints> make_image_points() const override {
    return make_device_image_points();
  }
  std::string device_name() const override { return cuda::device_name(); }
  std::string runtime_version() const override { return cuda::runtime_version(); }
};

}  // namespace

const DeviceServices& device_services() {
  static const CudaServices services;
  return services;
}

}  // namespace raycut::detail::cuda
