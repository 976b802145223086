#include "errors.hpp"

#include <cstdio>
#include <exception>

namespace nb = nanobind;

namespace raycut_py {

namespace {

PyObject* capacity_error = nullptr;  // raycut.CapacityError(RuntimeError)

}  // namespace

std::string number(double value) {
  char text[32];
  std::snprintf(text, sizeof text, "%.6g", value);
  return text;
}

void bind_errors(nb::module_& m) {
  capacity_error = PyErr_NewExceptionWithDoc(
      "raycut.CapacityError",
      "A fixed-size output (the padded neighbour list) is too small: grow it and retry.",
      PyExc_RuntimeError, nullptr);
  m.attr("CapacityError") = nb::handle(capacity_error);

  // raycut::Error -> the Python exception of its code, with the library's message.
  nb::register_exception_translator([](const std::exception_ptr& p, void*) {
    try {
      std::rethrow_exception(p);
    } catch (const raycut::Error& e) {
      PyObject* type = PyExc_RuntimeError;
      switch (e.code()) {
        case raycut::ErrorCode::invalid_argument:
        case raycut::ErrorCode::invalid_input:
          type = PyExc_ValueError;
          break;
        case raycut::ErrorCode::out_of_memory:
          type = PyExc_MemoryError;
          break;
        case raycut::ErrorCode::unsupported:
          type = PyExc_NotImplementedError;
          break;
        case raycut::ErrorCode::io:
          type = PyExc_OSError;
          break;
        case raycut::ErrorCode::capacity_exceeded:
          type = capacity_error;
          break;
        case raycut::ErrorCode::backend:
        case raycut::ErrorCode::internal:
          type = PyExc_RuntimeError;
          break;
      }
      PyErr_SetString(type, e.what());
    }
  });
}

}  // namespace raycut_py
