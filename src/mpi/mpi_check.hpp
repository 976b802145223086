// MPI return codes as raycut errors (communicators default to MPI_ERRORS_ARE_FATAL; a caller
// who sets MPI_ERRORS_RETURN gets an Error(backend) naming the call instead).
#pragma once

#include <mpi.h>

#include <string>

#include "raycut/error.hpp"

namespace raycut::mpi {

inline void check(int rc, const char* call) {
  if (rc == MPI_SUCCESS) return;
  char text[MPI_MAX_ERROR_STRING];
  int length = 0;
  MPI_Error_string(rc, text, &length);
  throw Error(ErrorCode::backend, std::string(call) + " failed: " + std::string(text, length));
}

}  // namespace raycut::mpi
