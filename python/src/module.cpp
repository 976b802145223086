// pyraycut._raycut: the nanobind extension under the pyraycut Python package (python/pyraycut). It
// reads positions from anything with DLPack (NumPy, PyTorch, CuPy, JAX) or
// __cuda_array_interface__, without a copy, and returns arrays that wrap the library's own
// buffers (a capsule keeps them alive): NumPy arrays on the host, DLPack-capable arrays on the
// device that the Python layer hands to the caller's framework (from_dlpack, zero-copy).
//
// One file per job: arrays.hpp/.cpp (arrays in and out: conversions and checks), errors.hpp/.cpp
// (bad arguments and the translation of raycut::Error), engine.hpp (the Python Engine and the lock
// it shares with VerletList), functions_bindings.cpp, engine_bindings.cpp, kernels_bindings.cpp
// (compute, results, the kernel catalogue) and verlet_bindings.cpp; device.hpp/.cu with CUDA.
#include <nanobind/nanobind.h>

#include "bindings.hpp"
#include "errors.hpp"

NB_MODULE(_raycut, m) {
  m.doc() = "raycut's C++ engine (nanobind); use the raycut package, not this module directly.";

  raycut_py::bind_errors(m);
  raycut_py::bind_functions(m);
  raycut_py::bind_engine(m);
  raycut_py::bind_verlet(m);
}
