// Factories of the CUDA methods (host-only declarations; the classes live in their .cu files).
#pragma once

#include <memory>

#include "core/device_services.hpp"
#include "core/method.hpp"

namespace raycut::detail::cuda {

std::unique_ptr<Method> make_brute_force();

// The seed paper's dense grid (cells of width C over the whole box), for comparison.
std::unique_ptr<Method> make_grid_paper();

// The production grid; its choices are automatic (grid_policy.hpp, measured in docs/grid.md).
// A policy forces them: bench/grid_tune.cpp measures the alternatives, the tests run each path.
struct GridPolicy;
std::unique_ptr<Method> make_grid_with(const GridPolicy& policy);
std::unique_ptr<Method> make_grid();

// The engine's device services (core/device_services.hpp) on the CUDA runtime.
const DeviceServices& device_services();

}  // namespace raycut::detail::cuda
