// Device copies of positions for host-only callers, and what a benchmark ran on.
#include <cctype>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>
#include <utility>

#include "core/device_services.hpp"
#include "raycut/engine.hpp"

namespace raycut {

DeviceArray::DeviceArray(const std::vector<float>& values) : size_(values.size()) {
  const detail::DeviceServices* device = detail::device_services();
  if (!device)
    throw Error(ErrorCode::unsupported, "device arrays need CUDA; raycut was built without it");
  if (size_ > 0)
    data_ =
        static_cast<float*>(device->upload(values.data(), values.size() * sizeof(float)).release());
}

DeviceArray::~DeviceArray() {
  if (data_) detail::device_services()->free(data_);  // data_ was made by the same services
}

DeviceArray::DeviceArray(DeviceArray&& o) noexcept
    : data_(std::exchange(o.data_, nullptr)), size_(std::exchange(o.size_, 0)) {}

DeviceArray& DeviceArray::operator=(DeviceArray&& o) noexcept {
  std::swap(data_, o.data_);
  std::swap(size_, o.size_);
  return *this;
}

namespace {

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
  const detail::DeviceServices* device = detail::device_services();
  if (device && device->available()) {
    info.gpu = device->device_name();
    info.driver = nvidia_driver_version();
    info.cuda = device->runtime_version();
  }
  if (std::string optix = detail::optix_headers_version(); !optix.empty()) info.optix = optix;
  return info;
}

}  // namespace raycut
