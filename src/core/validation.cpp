#include "core/validation.hpp"

#include <cmath>
#include <cstdio>
#include <limits>
#include <new>
#include <stdexcept>
#include <string>

#include "raycut/detail/host_threads.hpp"
#include "raycut/error.hpp"
#include "raycut/host_memory.hpp"

namespace raycut::detail {

// A value in messages: three significant digits.
std::string number(double value) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%.3g", value);
  return buf;
}

void validate_cutoff(float cutoff) {
  validate_cutoff_value(cutoff);
}

void validate_cutoff_value(double cutoff) {
  if (!std::isfinite(cutoff) || !(cutoff > 0.0))
    throw Error(ErrorCode::invalid_argument,
                "cutoff must be finite and > 0, got " + number(cutoff));
  if (cutoff < min_cutoff || cutoff > max_cutoff)
    throw Error(ErrorCode::invalid_argument,
                "cutoff " + number(cutoff) + " is outside the supported range [2^-60, 2^60] = [" +
                    number(min_cutoff) + ", " + number(max_cutoff) +
                    "]: beyond it the squared cutoff is not a normal float and the float "
                    "predicate would be wrong (scale your coordinates and cutoff into it)");
}

std::size_t first_non_finite_host(const float* xyz, std::size_t n) {
  std::size_t first = n;
  // Parallel scan; the minimum bad index keeps the message deterministic.
#pragma omp parallel for reduction(min : first) schedule(static) if (n >= parallel_items)
  for (std::size_t i = 0; i < n; ++i) {
    if (!std::isfinite(xyz[3 * i]) || !std::isfinite(xyz[3 * i + 1]) ||
        !std::isfinite(xyz[3 * i + 2]))
      first = i < first ? i : first;
  }
  return first;
}

void throw_non_finite(std::size_t index, const float* p, const char* what) {
  char buf[160];
  std::snprintf(buf, sizeof buf, "non-finite coordinate at %s index %zu: (%g, %g, %g)", what, index,
                static_cast<double>(p[0]), static_cast<double>(p[1]), static_cast<double>(p[2]));
  throw Error(ErrorCode::invalid_input, buf);
}

void allocate_indices(NeighbourList& list, std::uint64_t pairs) {
  auto too_large = [&] {
    return Error(ErrorCode::out_of_memory,
                 "not enough host memory for the neighbour list: " + std::to_string(pairs) +
                     " pairs need " + format_bytes(static_cast<double>(pairs) * 4));
  };
  require_host_memory(static_cast<double>(pairs) * 4,
                      "a neighbour list of " + std::to_string(pairs) + " pairs");
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

namespace raycut {

using detail::number;

float checked_cutoff(double cutoff) {
  detail::validate_cutoff_value(cutoff);
  return static_cast<float>(cutoff);
}

void validate_kernel_range(Kernel kernel, const KernelOptions& options, float cutoff) {
  constexpr double pi = 3.14159265358979;  // as kernels.hpp (its float pi, widened)
  constexpr double float_max = std::numeric_limits<float>::max();
  constexpr double float_min = std::numeric_limits<float>::min();  // smallest normal
  const std::string name = to_string(kernel);
  // `value` must be a finite float and, unless it is legitimately zero, not below the smallest
  // normal float (a subnormal or zero largest term has lost its relative precision).
  auto require = [&](const char* what, double value, bool may_be_zero) {
    const double magnitude = std::fabs(value);
    const bool overflows = !(magnitude <= float_max);
    const bool underflows = !overflows && magnitude < float_min && !(may_be_zero && value == 0);
    if (!overflows && !underflows) return;
    throw Error(ErrorCode::invalid_argument,
                "kernel " + name + " cannot be evaluated in float at cutoff " + number(cutoff) +
                    ": its " + what + " = " + number(value) +
                    (overflows ? " overflows" : " underflows") + " float (range [" +
                    number(float_min) + ", " + number(float_max) + "])" +
                    (kernel == Kernel::smooth
                         ? "; smooth supports cutoffs in [" + number(std::pow(float_min, 0.25)) +
                               ", " + number(std::pow(float_max, 0.25)) + "]"
                         : std::string()));
  };
  // What the kernels see: the squared cutoff rounded to float, h its float square root.
  const double c2 = static_cast<float>(static_cast<double>(cutoff) * cutoff);
  const double h = std::sqrt(static_cast<float>(c2));
  const double mass = options.sph_mass;
  switch (kernel) {
    case Kernel::count:
      return;
    case Kernel::lj:
    case Kernel::lj_forces: {
      const double sigma6 = std::pow(static_cast<double>(options.lj_sigma), 6);
      const bool zero = options.lj_sigma == 0.0f || options.lj_epsilon == 0.0f;
      require("sigma^6", sigma6, options.lj_sigma == 0.0f);
      require("factor 4 eps sigma^6", 4.0 * options.lj_epsilon * sigma6, zero);
      return;
    }
    case Kernel::smooth:
      require("largest energy term (C^2)^2", c2 * c2, false);
      require("largest force term C^2 * C", c2 * cutoff, false);
      return;
    case Kernel::sph_density: {
      const double factor = mass * 315.0 / (64.0 * pi * std::pow(h, 9));
      require("factor m 315 / (64 pi h^9)", factor, mass == 0);
      require("largest raw term (h^2)^3", c2 * c2 * c2, false);
      require("largest pair term m 315 / (64 pi h^9) h^6", factor * c2 * c2 * c2, mass == 0);
      return;
    }
    case Kernel::sph_force: {
      const double spiky = 45.0 / (pi * std::pow(h, 6));
      const double viscosity = options.sph_viscosity;
      require("factor 45 / (pi h^6)", spiky, false);
      require("pressure factor per unit p / rho, m 45 / (pi h^6)", mass * spiky, mass == 0);
      require("viscosity factor per unit v / rho, mu m 45 / (pi h^6)", viscosity * mass * spiky,
              viscosity * mass == 0);
      require("largest pressure term per unit p / rho, m 45 / (pi h^6) h^2", mass * spiky * c2,
              mass == 0);
      require("largest viscosity term per unit v / rho, mu m 45 / (pi h^6) h",
              viscosity * mass * spiky * h, viscosity * mass == 0);
      return;
    }
  }
}

}  // namespace raycut
