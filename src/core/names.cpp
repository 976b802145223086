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
    case ErrorCode::capacity_exceeded:
      return "capacity exceeded";
    case ErrorCode::internal:
      return "internal error";
  }
  return "error";
}

namespace {
constexpr Kernel all_kernels[] = {Kernel::count,  Kernel::lj,          Kernel::lj_forces,
                                  Kernel::smooth, Kernel::sph_density, Kernel::sph_force};
}  // namespace

Kernel parse_kernel(std::string_view name) {
  std::string known;
  for (Kernel k : all_kernels) {
    if (name == to_string(k)) return k;
    known += (known.empty() ? "" : ", ") + to_string(k);
  }
  throw Error(ErrorCode::invalid_argument,
              "unknown kernel '" + std::string(name) + "' (known: " + known + ")");
}

std::string to_string(Kernel kernel) {
  switch (kernel) {
    case Kernel::count:
      return "count";
    case Kernel::lj:
      return "lj";
    case Kernel::lj_forces:
      return "lj_forces";
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
