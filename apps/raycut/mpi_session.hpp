// MPI for the raycut tool's --distributed runs (built with raycut::mpi): MPI_Init when the process
// has not (the tool does not otherwise use MPI), and MPI_Finalize on the way out, also when an
// error unwinds every rank.
#pragma once

#include <mpi.h>

namespace raycut::cli {

struct MpiSession {
  bool owner = false;
  MpiSession() {
    int initialized = 0;
    MPI_Initialized(&initialized);
    if (!initialized) {
      MPI_Init(nullptr, nullptr);
      owner = true;
    }
  }
  ~MpiSession() {
    int finalized = 0;
    MPI_Finalized(&finalized);
    if (owner && !finalized) MPI_Finalize();
  }
  MpiSession(const MpiSession&) = delete;
  MpiSession& operator=(const MpiSession&) = delete;
};

}  // namespace raycut::cli
