// The extension's errors: bad arguments raised as raycut::Error (a Python ValueError), the values
// their messages quote, and the translation of raycut::Error into Python exceptions.
#pragma once

#include <nanobind/nanobind.h>

#include <string>

#include "raycut/error.hpp"

namespace raycut_py {

[[noreturn]] inline void value_error(const std::string& message) {
  throw raycut::Error(raycut::ErrorCode::invalid_argument, message);
}

// A value in messages ("1e-50", "0.25").
std::string number(double value);

// raycut.CapacityError on `m`, and raycut::Error -> the Python exception of its code.
void bind_errors(nanobind::module_& m);

}  // namespace raycut_py
