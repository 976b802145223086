// Host memory up front: a request that cannot fit is refused with a message naming the memory it
// needs, the budget and the knob that sets it, instead of a bare std::bad_alloc or the kernel's
// OOM killer later (which overcommit makes the usual outcome: `resize` rarely throws).
#pragma once

#include <string>
#include <type_traits>

#include "raycut/error.hpp"

namespace raycut {

// What one new host allocation may take, and where that figure comes from.
struct MemoryBudget {
  double bytes = 0;
  // "RAYCUT_MAX_MEMORY=300M", or what the system figure is: "the memory available (MemAvailable
  // 1.20 GiB; cgroup limit 2.00 GiB minus 0.80 GiB in use)".
  std::string source;
  bool from_environment = false;
};

// The budget of one host allocation:
// - RAYCUT_MAX_MEMORY when set: bytes, with an optional K, M, G or T suffix (powers of 1024:
//   300M = 300 x 2^20 bytes), a whole or decimal number; anything else is
//   Error(invalid_argument) naming the variable, its value and the accepted form;
// - otherwise the smaller of MemAvailable (/proc/meminfo) and the headroom of every memory
//   cgroup above this process (v2: memory.max minus memory.current; v1: memory.limit_in_bytes
//   minus memory.usage_in_bytes; reclaimable page cache, inactive_file, not counted as used).
MemoryBudget host_memory_budget();

// The bytes of host_memory_budget() (kept for callers of the older interface).
double available_host_memory();

// Throws Error(out_of_memory) when `bytes` (an estimate, in double so that it cannot overflow) is
// more than the budget: "<what> needs 3.20 GiB of host memory, more than the budget: 300.00 MiB
// is available (RAYCUT_MAX_MEMORY=300M; ...)". Requests below 16 MiB are not compared with the
// system's figures (reading them costs more than such an allocation), only with RAYCUT_MAX_MEMORY.
void require_host_memory(double bytes, const std::string& what);

// Whether require_host_memory compares `bytes` with the budget at all: 16 MiB or more, or any
// request while RAYCUT_MAX_MEMORY is set.
bool host_memory_checked(double bytes);

// The same, with <what> made by `describe()` only when the request is compared: for the checks
// on every call's path, where formatting messages that are almost never shown was 8 % of the
// instructions of a 1-atom cell's build and list (callgrind; 12.1 -> 11.0 us a call).
template <class Describe,
          std::enable_if_t<std::is_invocable_r_v<std::string, Describe>, int> = 0>  // C++17: nvcc
void require_host_memory(double bytes, Describe&& describe) {
  if (host_memory_checked(bytes)) require_host_memory(bytes, std::string(describe()));
}

}  // namespace raycut
