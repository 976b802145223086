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

Kernel parse_kernel(std::string_view name) {
  Kernel found{};
  bool known_name = false;
  std::string known;
  for_each_kernel([&](auto spec) {
    using Spec = decltype(spec);
    if (name == Spec::name) {
      found = Spec::id;
      known_name = true;
    }
    known += (known.empty() ? "" : ", ") + std::string(Spec::name);
  });
  if (known_name) return found;
  throw Error(ErrorCode::invalid_argument,
              "unknown kernel '" + std::string(name) + "' (known: " + known + ")");
}

std::string to_string(Kernel kernel) {
  std::string name = "?";
  visit_kernel(kernel, [&](auto spec) { name = decltype(spec)::name; });
  return name;
}

}  // namespace raycut
