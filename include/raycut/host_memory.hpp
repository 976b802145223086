// Host memory up front: a request that cannot fit is refused with a message naming the memory it
// needs and the memory there is, instead of a bare std::bad_alloc (or the OOM killer) later.
#pragma once

#include <string>

#include "raycut/error.hpp"

namespace raycut {

// Bytes of host memory a new allocation can get: MemAvailable of /proc/meminfo (free memory plus
// what the kernel can reclaim, such as the page cache), else sysconf's available pages, else the
// physical memory.
double available_host_memory();

// Throws Error(out_of_memory) when `bytes` (an estimate, in double so that it cannot overflow) is
// more than the available host memory: "<what> needs 3.2 GiB of host memory, 1.1 GiB is
// available".
void require_host_memory(double bytes, const std::string& what);

}  // namespace raycut
