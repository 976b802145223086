// Device copies of positions for host-only callers, and what a benchmark ran on.
#include <cctype>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <utility>

#include "raycut/engine.hpp"
#if defined(RAYCUT_HAVE_CUDA)
#include "cuda/runtime.hpp"
#endif

namespace raycut {

DeviceArray::DeviceArray(const std::vector<float>& values) : size_(values.size()) {
#if defined(RAYCUT_HAVE_CUDA)
  if (size_ > 0)
    data_ = static_cast<float*>(
        detail::cuda::upload(values.data(), values.size() * sizeof(float)).release());
#else
  throw Error(ErrorCode::unsupported, "device arrays need CUDA; raycut was built without it");
#endif
}

DeviceArray::~DeviceArray() {
#if defined(RAYCUT_HAVE_CUDA)
  detail::cuda::DeviceFree{}(data_);
#endif
}

DeviceArray::DeviceArray(DeviceArray&& o) noexcept
    : data_(std::exchange(o.data_, nullptr)), size_(std::exchange(o.size_, 0)) {}

DeviceArray& DeviceArray::operator=(DeviceArray&& o) noexcept {
  std::swap(data_, o.data_);
  std::swap(size_, o.size_);
  return *this;
}

namespace {

#if defined(RAYCUT_HAVE_CUDA)
// "580.159.04": the first dotted number on the kernel module's version line ("NVRM version:
// NVIDIA UNIX Open Kernel Module for x86_64  580.159.04  Release Build ..."), or "unknown".
std::string nvidia_driver_version() {
  std::ifstream in("/proc/driver/nvidia/version");
  std::string word;
  while (in >> word) {
    const bool dotted_number = !word.empty() && std::isdigit(static_cast<unsigned char>(word[0])) &&
                               word.find('.') != std::string::npos;
    if (dotted_number) return word;
  }
  return "unknown";
}
#endif

std::string cpu_model() {
  std::ifstream in("/proc/cpuinfo");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("model name", 0) == 0) {
      const auto colon = line.find(':');
      if (colon != std::string::npos) {
        std::string model = line.substr(colon + 1);
        model.erase(0, model.find_first_not_of(' '));
        return model;
      }
    }
  }
  return "unknown cpu";
}

}  // namespace

SystemInfo system_info() {
  SystemInfo info{"none", "none", "none", "none", ""};
  std::ostringstream cpu;
  cpu << cpu_model() << " (" << std::thread::hardware_concurrency() << " threads)";
  info.cpu = cpu.str();
#if defined(RAYCUT_HAVE_CUDA)
  if (detail::cuda::device_available()) {
    info.gpu = detail::cuda::device_name();
    info.driver = nvidia_driver_version();
    info.cuda = detail::cuda::runtime_version();
  }
#endif
#if defined(RAYCUT_OPTIX_VERSION)
  info.optix = std::to_string(RAYCUT_OPTIX_VERSION / 10000) + "." +
               std::to_string(RAYCUT_OPTIX_VERSION % 10000 / 100) + "." +
               std::to_string(RAYCUT_OPTIX_VERSION % 100);
#endif
  return info;
}

}  // namespace raycut
