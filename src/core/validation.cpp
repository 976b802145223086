#include "core/validation.hpp"

#include <cmath>
#include <cstdio>
#include <new>
#include <stdexcept>
#include <string>

#include "raycut/error.hpp"

namespace raycut::detail {

void validate_cutoff(float cutoff) {
  if (!std::isfinite(cutoff) || !(cutoff > 0.0f))
    throw Error(ErrorCode::invalid_argument,
                "cutoff must be finite and > 0, got " + std::to_string(cutoff));
}

std::size_t first_non_finite_host(const float* xyz, std::size_t n) {
  std::size_t first = n;
  // Parallel scan; the minimum bad index keeps the message deterministic.
#pragma omp parallel for reduction(min : first) schedule(static)
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(xyz[3 * i]) || !std::isfinite(xyz[3 * i + 1]) ||
        !std::isfinite(xyz[3 * i + 2]))
      first = i < first ? i : first;
  }
  return first;
}

void throw_non_finite(std::size_t index, const float* p) {
  char buf[160];
  std::snprintf(buf, sizeof buf, "non-finite coordinate at particle index %zu: (%g, %g, %g)", index,
                static_cast<double>(p[0]), static_cast<double>(p[1]), static_cast<double>(p[2]));
  throw Error(ErrorCode::invalid_input, buf);
}

void allocate_indices(NeighbourList& list, std::uint64_t pairs) {
  auto too_large = [&] {
    return Error(ErrorCode::out_of_memory,
                 "not enough host memory for the neighbour list: " + std::to_string(pairs) +
                     " pairs need " + format_bytes(static_cast<double>(pairs) * 4));
  };
  try {
    list.indices.resize(pairs);
  } catch (const std::bad_alloc&) {
    throw too_large();
  } catch (const std::length_error&) {
    throw too_large();
  }
}

std::string format_bytes(double bytes) {
  const char* units[] = {"B", "KiB", "MiB", "GiB", "TiB", "PiB"};
  int u = 0;
  while (bytes >= 1024.0 && u < 5) {
    bytes /= 1024.0;
    ++u;
  }
  char buf[32];
  std::snprintf(buf, sizeof buf, u == 0 ? "%.0f %s" : "%.2f %s", bytes, units[u]);
  return buf;
}

}  // namespace raycut::detail
