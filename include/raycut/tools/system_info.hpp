// The machine results were measured on, for benchmark rows and `raycut --version`-style reports.
#pragma once

#include <string>

namespace raycut {

struct SystemInfo {
  std::string gpu;     // device name, or "none"
  std::string driver;  // NVIDIA driver version, or "none"
  std::string cuda;    // CUDA runtime version, e.g. "13.0", or "none"
  std::string optix;   // OptiX headers version built against, or "none"
  std::string cpu;     // CPU model and thread count
};

// Never throws for a missing device: the GPU fields are then "none".
SystemInfo system_info();

}  // namespace raycut
