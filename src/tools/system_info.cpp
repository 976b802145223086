// SystemInfo: the CPU from /proc, the GPU and runtime from the library's device services.
#include "raycut/tools/system_info.hpp"

#include <cctype>
#include <fstream>
#include <sstream>
#include <string>
#include <thread>

#include "core/device_services.hpp"

namespace raycut {

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
