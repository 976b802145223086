// Host memory up front: a request that cannot fit is refused with a message naming the memory it
// needs and the memory there is, instead of a bare std::bad_alloc (or the OOM killer) later.
#pragma once

#include <unistd.h>

#include <cstdint>
#include <fstream>
#include <string>

#include "core/validation.hpp"
#include "raycut/error.hpp"

namespace raycut::detail {

// Bytes of host memory a new allocation can get: MemAvailable of /proc/meminfo (free memory plus
// what the kernel can reclaim, such as the page cache), else sysconf's available pages, else the
// physical memory.
inline double available_host_memory() {
  std::ifstream meminfo("/proc/meminfo");
  std::string key;
  double kib = 0;
  std::string unit;
  while (meminfo >> key >> kib >> unit)
    if (key == "MemAvailable:") return kib * 1024.0;
  const long page = ::sysconf(_SC_PAGESIZE);
  const long available = ::sysconf(_SC_AVPHYS_PAGES);
  if (page > 0 && available > 0) return static_cast<double>(available) * page;
  const long physical = ::sysconf(_SC_PHYS_PAGES);
  return page > 0 && physical > 0 ? static_cast<double>(physical) * page : 1e300;
}

// Throws Error(out_of_memory) when `bytes` (an estimate, in double so that it cannot overflow) is
// more than the available host memory: "<what> needs 3.2 GiB of host memory, 1.1 GiB is
// available".
inline void require_host_memory(double bytes, const std::string& what) {
  const double available = available_host_memory();
  if (bytes > available)
    throw Error(ErrorCode::out_of_memory, what + " needs " + format_bytes(bytes) +
                                              " of host memory, " + format_bytes(available) +
                                              " is available");
}

}  // namespace raycut::detail
