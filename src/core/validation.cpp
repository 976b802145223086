#include "core/validation.hpp"

#include <algorithm>
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

namespace {
// The first of `count` values that is not finite and >= 0, or count.
std::size_t first_bad_cutoff(const double* values, std::size_t count) {
  for (std::size_t k = 0; k < count; ++k)
    if (!std::isfinite(values[k]) || values[k] < 0) return k;
  return count;
}
}  // namespace

void validate_pair_cutoffs(const PairCutoffs& cutoffs, std::size_t n, double search) {
  const auto refuse = [](const std::string& why) {
    throw Error(ErrorCode::invalid_argument, "per-pair cutoffs: " + why);
  };
  if (cutoffs.radii && (cutoffs.table || cutoffs.species))
    refuse("give radii or a species table, not both");
  double largest = 0;
  if (cutoffs.radii) {
    if (const std::size_t k = first_bad_cutoff(cutoffs.radii, n); k < n)
      refuse("radius " + std::to_string(k) + " is " + number(cutoffs.radii[k]) +
             " (finite and >= 0 accepted)");
    for (std::size_t i = 0; i < n; ++i) largest = std::max(largest, 2 * cutoffs.radii[i]);
  } else {
    const std::size_t kinds = cutoffs.kinds;
    if (kinds == 0) refuse("a species table needs kinds >= 1, got 0");
    if (!cutoffs.species && n > 0) refuse("a species table needs the species of the particles");
    for (std::size_t i = 0; i < n; ++i)
      if (cutoffs.species[i] >= kinds)
        refuse("particle " + std::to_string(i) + " has species " +
               std::to_string(cutoffs.species[i]) + ", outside the table's [0, " +
               std::to_string(kinds) + ")");
    if (const std::size_t k = first_bad_cutoff(cutoffs.table, kinds * kinds); k < kinds * kinds)
      refuse("table[" + std::to_string(k / kinds) + "][" + std::to_string(k % kinds) + "] is " +
             number(cutoffs.table[k]) + " (finite and >= 0 accepted)");
    for (std::size_t a = 0; a < kinds; ++a)
      for (std::size_t b = 0; b < a; ++b)
        if (cutoffs.table[a * kinds + b] != cutoffs.table[b * kinds + a])
          refuse("the table is not symmetric: [" + std::to_string(a) + "][" + std::to_string(b) +
                 "] = " + number(cutoffs.table[a * kinds + b]) + ", [" + std::to_string(b) + "][" +
                 std::to_string(a) + "] = " + number(cutoffs.table[b * kinds + a]));
    for (std::size_t k = 0; k < kinds * kinds; ++k) largest = std::max(largest, cutoffs.table[k]);
  }
  // Full precision: the two may differ only in the rounding of the engine's float cutoff.
  const auto exact_number = [](double value) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%.9g", value);
    return std::string(buf);
  };
  if (largest > search)
    refuse("a pair cutoff of " + exact_number(largest) + " exceeds the engine's cutoff " +
           exact_number(search) + ", where the search runs (build at the largest pair cutoff" +
           (cutoffs.radii ? ": 2 max r_i with radii, since a particle pairs with its images" : "") +
           ")");
}

std::size_t first_non_finite_host(const float* xyz, std::size_t n) {
  const auto bad = [xyz](std::size_t i) {
    return !std::isfinite(xyz[3 * i]) || !std::isfinite(xyz[3 * i + 1]) ||
           !std::isfinite(xyz[3 * i + 2]);
  };
  // Below parallel_items no OpenMP region at all (host_threads.hpp, for_each_index says why).
  if (n < parallel_items) {
    for (std::size_t i = 0; i < n; ++i)
      if (bad(i)) return i;
    return n;
  }
  std::size_t first = n;
  // Parallel scan; the minimum bad index keeps the message deterministic.
#pragma omp parallel for reduction(min : first) schedule(static)
  for (std::size_t i = 0; i < n; ++i)
    if (bad(i)) first = i < first ? i : first;
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
                      [&] { return "a neighbour list of " + std::to_string(pairs) + " pairs"; });
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
  constexpr double float_max = std::numeric_limits<float>::max();
  constexpr double float_min = std::numeric_limits<float>::min();  // smallest normal
  const std::string name = to_string(kernel);
  // `value` must be a finite float and, unless it is legitimately zero, not below the smallest
  // normal float (a subnormal or zero largest term has lost its relative precision).
  auto require = [&](const char* what, double value, bool may_be_zero, double lowest_cutoff = 0,
                     double highest_cutoff = 0) {
    const double magnitude = std::fabs(value);
    const bool overflows = !(magnitude <= float_max);
    const bool underflows = !overflows && magnitude < float_min && !(may_be_zero && value == 0);
    if (!overflows && !underflows) return;
    throw Error(
        ErrorCode::invalid_argument,
        "kernel " + name + " cannot be evaluated in float at cutoff " + number(cutoff) + ": its " +
            what + " = " + number(value) + (overflows ? " overflows" : " underflows") +
            " float (range [" + number(float_min) + ", " + number(float_max) + "])" +
            (highest_cutoff > 0 ? "; " + name + " supports cutoffs in [" + number(lowest_cutoff) +
                                      ", " + number(highest_cutoff) + "]"
                                : std::string()));
  };
  // What the kernels see: the squared cutoff rounded to float, h its float square root.
  const double c2 = static_cast<float>(static_cast<double>(cutoff) * cutoff);
  const KernelScale scale{cutoff, c2, std::sqrt(static_cast<float>(c2))};
  visit_kernel(kernel, [&](auto spec) {
    using Spec = decltype(spec);
    Spec::check_range(options, scale, require);
    for (const KernelParameter& p : Spec::parameters) {
      if (!p.value) continue;  // a flag
      const double value = options.*p.value;
      if (std::isfinite(value) && value >= p.min && value <= p.max) continue;
      throw Error(ErrorCode::invalid_argument, "kernel " + name + ": parameter " +
                                                   std::string(p.name) + " = " + number(value) +
                                                   " is not accepted (finite values in [" +
                                                   number(p.min) + ", " + number(p.max) + "])");
    }
  });
}

void validate_kernel_inputs(Kernel kernel, const KernelOptions& options, bool query_points) {
  const std::string name = to_string(kernel);
  visit_kernel(kernel, [&](auto spec) {
    using Spec = decltype(spec);
    for (const KernelInput& input : Spec::inputs) {
      const bool given = input_pointer(input, options) != nullptr;
      const std::string what = std::string(input.name);
      if (query_points && input.end == InputEnd::both)
        throw Error(ErrorCode::unsupported,
                    "kernel " + name + " with query points: its input " + what +
                        " is read for the target and the source of each pair from one array; "
                        "build without query points (the targets are then the sources)");
      if (input.end == InputEnd::queries && given != query_points)
        throw Error(ErrorCode::invalid_argument,
                    "kernel " + name + ": input " + what +
                        (query_points ? " is missing: with query points it gives the queries' "
                                        "values (one per query)"
                                      : " is given without query points: it is the queries' "
                                        "values (without query points the targets are the "
                                        "sources and read the sources' array)"));
    }
  });
}

}  // namespace raycut
