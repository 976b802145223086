// The pieces of pyraycut._raycut that module.cpp wires together (one file each), and the kernel
// calls of Engine (kernels_bindings.cpp) that engine_bindings.cpp binds.
#pragma once

#include <nanobind/nanobind.h>

#include <string_view>

#include "engine.hpp"

namespace raycut_py {

// Module-level functions: methods, kernel_catalogue, auto_method, the CUDA device and, with
// CUDA, the batch index on the device (functions_bindings.cpp).
void bind_functions(nb::module_& m);
// The class Engine (engine_bindings.cpp).
void bind_engine(nb::module_& m);
// The class VerletList (verlet_bindings.cpp).
void bind_verlet(nb::module_& m);

// run() and its results in one locked call: another thread's run() in between would take them.
// `parameters` maps parameter names to numbers (or flags), `inputs` input names to arrays
// (raycut's kernel catalogue, kernel_catalogue()).
nb::dict compute(PyEngine& locked_engine, std::string_view kernel_name, nb::dict parameters,
                 nb::dict inputs, bool to_host);
// The results of the last run() of `kernel_name`, where asked (`to_host`) or where they are.
nb::dict results(PyEngine& locked_engine, std::string_view kernel_name, bool to_host);
// The built-in kernels (raycut's catalogue), in a stable order: per kernel its name, its
// parameters (name, type "float" or "bool", default, accepted [min, max]), its per-particle
// inputs (name, components, end: "both", "sources" or "queries", positive) and its outputs
// (name, components).
nb::list kernel_catalogue();

}  // namespace raycut_py
