// Which methods the tests can run here: every registered method is named (so a test lists what
// it skips), and a method that cannot run (no GPU, no OptiX) says why.
#pragma once

#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "raycut/engine.hpp"

namespace raycut_test {

// Every registered method, available here or not.
inline std::vector<std::string> every_method() {
  std::vector<std::string> names;
  for (const auto& m : raycut::list_methods()) names.push_back(m.name);
  return names;
}

// Why `method` cannot run here; empty when it can.
inline std::string unavailable(const std::string& method) {
  for (const auto& m : raycut::list_methods())
    if (m.name == method)
      return m.available ? "" : (m.why_unavailable.empty() ? "not available" : m.why_unavailable);
  ADD_FAILURE() << method << " is not in list_methods()";
  return "not in list_methods()";
}

}  // namespace raycut_test
