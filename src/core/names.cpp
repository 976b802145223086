// String forms of the public enums.
#include <string>

#include "raycut/error.hpp"
#include "raycut/kernels.hpp"

namespace raycut {

const char* to_string(ErrorCode code) noexcept {
  switch (code) {
    case ErrorCode::invalid_argument:
      return "invalid argument";
    case ErrorCode::invalid_input:
      return "invalid input";
    case ErrorCode::out_of_memory:
      return "out of memory";
    case ErrorCode::unsupported:
      return "unsupported";
    case ErrorCode::io:
      return "i/o error";
    case ErrorCode::backend:
      return "backend error";
    case ErrorCode::internal:
      return "internal error";
  }
  return "error";
}

Kernel parse_kernel(std::string_view name) {
  if (name == "count") return Kernel::count;
  if (name == "lj") return Kernel::lj;
  if (name == "smooth") return Kernel::smooth;
  if (name == "sph_density") return Kernel::sph_density;
  if (name == "sph_force") return Kernel::sph_force;
  throw Error(ErrorCode::invalid_argument, "unknown kernel '" + std::string(name) +
                                               "' (known: count, lj, smooth, sph_density, "
                                               "sph_force)");
}

std::string to_string(Kernel kernel) {
  switch (kernel) {
    case Kernel::count:
      return "count";
    case Kernel::lj:
      return "lj";
    case Kernel::smooth:
      return "smooth";
    case Kernel::sph_density:
      return "sph_density";
    case Kernel::sph_force:
      return "sph_force";
  }
  return "?";
}

}  // namespace raycut
