// Factories of the CUDA methods (host-only declarations; the classes live in their .cu files).
#pragma once

#include <memory>

#include "core/method.hpp"

namespace raycut::detail::cuda {

std::unique_ptr<Method> make_brute_force();

}  // namespace raycut::detail::cuda
