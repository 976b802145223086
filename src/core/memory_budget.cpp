// The host memory budget (raycut/host_memory.hpp): RAYCUT_MAX_MEMORY, or what the system and the
// memory cgroups this process runs in say is free. One implementation, used by every check.
#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "core/validation.hpp"
#include "raycut/host_memory.hpp"

namespace raycut {
namespace {

constexpr const char* knob = "RAYCUT_MAX_MEMORY";
// Below this, a request is compared with RAYCUT_MAX_MEMORY only: reading /proc and the cgroup
// files costs tens of microseconds, more than allocating (or filling) such a buffer.
constexpr double checked_from = 16.0 * 1024 * 1024;

[[noreturn]] void bad_knob(const std::string& value) {
  throw Error(ErrorCode::invalid_argument,
              std::string(knob) +
                  " must be a number of bytes > 0 with an optional K, M, G or T "
                  "suffix (powers of 1024), e.g. 300M or 2.5G; got '" +
                  value + "'");
}

// RAYCUT_MAX_MEMORY's value in bytes: "300M", "2.5G", "1048576", "64KiB", "1GB".
double parse_knob(const std::string& value) {
  std::size_t k = 0;
  while (k < value.size() &&
         (std::isdigit(static_cast<unsigned char>(value[k])) || value[k] == '.'))
    ++k;
  const std::string number = value.substr(0, k);
  if (number.empty() || std::count(number.begin(), number.end(), '.') > 1 || number == ".")
    bad_knob(value);
  std::string suffix = value.substr(k);
  for (char& c : suffix) c = static_cast<char>(std::toupper(static_cast<unsigned char>(c)));
  double scale = 1;
  if (!suffix.empty() && std::string("KMGT").find(suffix[0]) != std::string::npos) {
    scale = std::pow(1024.0, 1 + static_cast<int>(std::string("KMGT").find(suffix[0])));
    suffix.erase(0, 1);
    if (suffix == "IB" || suffix == "B") suffix.clear();
  } else if (suffix == "B") {
    suffix.clear();
  }
  if (!suffix.empty()) bad_knob(value);
  const double bytes = std::strtod(number.c_str(), nullptr) * scale;
  if (!(bytes >= 1) || !std::isfinite(bytes)) bad_knob(value);
  return bytes;
}

// The first number of a file ("max" and unreadable files: none, -1).
double read_number(const std::string& path) {
  std::ifstream in(path);
  std::string word;
  if (!(in >> word) || word.empty() || !std::isdigit(static_cast<unsigned char>(word[0])))
    return -1;
  return std::strtod(word.c_str(), nullptr);
}

// `key`'s value in a "key value" file (memory.stat), 0 if absent.
double read_stat(const std::string& path, const std::string& key) {
  std::ifstream in(path);
  std::string name;
  double value = 0;
  while (in >> name >> value)
    if (name == key) return value;
  return 0;
}

struct Headroom {
  double bytes = -1;  // < 0: no limit found
  double limit = 0, used = 0;
};

// The smallest headroom (limit minus use) of a cgroup folder and its ancestors up to `root`.
// v1 limits without a limit read as about 2^63: treated as none.
void cgroup_headroom(const std::string& root, std::string path, bool v2, Headroom& best) {
  for (;;) {
    const std::string dir = root + path;
    const double limit = read_number(dir + (v2 ? "/memory.max" : "/memory.limit_in_bytes"));
    if (limit > 0 && limit < 1e18) {
      const double usage = read_number(dir + (v2 ? "/memory.current" : "/memory.usage_in_bytes"));
      // Page cache the kernel reclaims before it kills: not counted as used (as `docker stats`).
      const double cache =
          read_stat(dir + "/memory.stat", v2 ? "inactive_file" : "total_inactive_file");
      const double used = std::max(0.0, usage - cache);
      const double room = std::max(0.0, limit - used);
      if (usage >= 0 && (best.bytes < 0 || room < best.bytes)) best = {room, limit, used};
    }
    if (path.empty() || path == "/") return;
    const std::size_t slash = path.find_last_of('/');
    path = slash == std::string::npos || slash == 0 ? std::string() : path.substr(0, slash);
  }
}

// The headroom of the memory cgroups this process is in (/proc/self/cgroup: "0::/path" for
// v2, "N:...memory...:/path" for v1). In a container the path may not exist under the mount
// (its own namespace shows "/"): the mount's root files are read then.
Headroom cgroup_headroom() {
  Headroom best;
  std::ifstream cgroups("/proc/self/cgroup");
  std::string line;
  while (std::getline(cgroups, line)) {
    const std::size_t a = line.find(':'), b = line.find(':', a + 1);
    if (a == std::string::npos || b == std::string::npos) continue;
    const std::string controllers = line.substr(a + 1, b - a - 1);
    const std::string path = line.substr(b + 1);
    std::vector<std::string> names;
    std::stringstream split(controllers);
    for (std::string c; std::getline(split, c, ',');) names.push_back(c);
    if (controllers.empty() && line.compare(0, a, "0") == 0) {
      cgroup_headroom("/sys/fs/cgroup", path, true, best);
    } else if (std::find(names.begin(), names.end(), "memory") != names.end()) {
      cgroup_headroom("/sys/fs/cgroup/memory", path, false, best);
    }
  }
  return best;
}

double mem_available() {
  std::ifstream meminfo("/proc/meminfo");
  std::string key, unit;
  double kib = 0;
  while (meminfo >> key >> kib >> unit)
    if (key == "MemAvailable:") return kib * 1024.0;
  const long page = ::sysconf(_SC_PAGESIZE);
  const long available = ::sysconf(_SC_AVPHYS_PAGES);
  if (page > 0 && available > 0) return static_cast<double>(available) * page;
  const long physical = ::sysconf(_SC_PHYS_PAGES);
  return page > 0 && physical > 0 ? static_cast<double>(physical) * page : 1e300;
}

const char* environment_value() {
  const char* value = std::getenv(knob);
  return value != nullptr && *value != '\0' ? value : nullptr;
}

}  // namespace

MemoryBudget host_memory_budget() {
  MemoryBudget budget;
  if (const char* value = environment_value()) {
    budget.bytes = parse_knob(value);
    budget.source = std::string(knob) + "=" + value;
    budget.from_environment = true;
    return budget;
  }
  using detail::format_bytes;
  const double available = mem_available();
  const Headroom cgroup = cgroup_headroom();
  budget.source = "the memory available: MemAvailable " + format_bytes(available);
  budget.bytes = available;
  if (cgroup.bytes >= 0) {
    budget.source += ", the container's cgroup limit " + format_bytes(cgroup.limit) + " minus " +
                     format_bytes(cgroup.used) + " in use";
    budget.bytes = std::min(available, cgroup.bytes);
  }
  return budget;
}

double available_host_memory() {
  return host_memory_budget().bytes;
}

bool host_memory_checked(double bytes) {
  return bytes >= checked_from || environment_value() != nullptr;
}

void require_host_memory(double bytes, const std::string& what) {
  if (!host_memory_checked(bytes)) return;
  const MemoryBudget budget = host_memory_budget();
  if (bytes <= budget.bytes) return;
  using detail::format_bytes;
  throw Error(
      ErrorCode::out_of_memory,
      what + " needs " + format_bytes(bytes) + " of host memory, more than the budget: " +
          format_bytes(budget.bytes) + " is available (" + budget.source +
          (budget.from_environment ? "; raise RAYCUT_MAX_MEMORY to allow more)"
                                   : "; RAYCUT_MAX_MEMORY=<bytes, K/M/G suffix> sets the budget)"));
}

}  // namespace raycut
