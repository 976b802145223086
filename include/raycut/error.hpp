// The one exception type raycut throws: what went wrong, and where.
#pragma once

#include <stdexcept>
#include <string>

namespace raycut {

enum class ErrorCode {
  invalid_argument,  // a bad parameter: cutoff <= 0, unknown method name, bad N
  invalid_input,     // bad data: NaN/Inf coordinate (the message names the index)
  out_of_memory,     // the request would need more memory than there is (the message says how much)
  unsupported,       // not available in this build or on this machine (no GPU, no OptiX)
  io,                // a file could not be read or written, or is malformed (file:line)
  backend,           // CUDA or OptiX reported an error (the message carries its text)
  capacity_exceeded,  // a fixed-size output (padded neighbour list) is too small: grow it
  internal,           // a broken invariant inside raycut: a bug, please report it
};

const char* to_string(ErrorCode code) noexcept;

class Error : public std::runtime_error {
 public:
  Error(ErrorCode code, const std::string& message) : std::runtime_error(message), code_(code) {}
  ErrorCode code() const noexcept { return code_; }

 private:
  ErrorCode code_;
};

}  // namespace raycut
