// What the tests ask of an error: that the action throws raycut::Error with the expected code;
// its message comes back for the test to read.
#pragma once

#include <gtest/gtest.h>

#include <functional>
#include <string>

#include "raycut/error.hpp"

namespace raycut_test {

inline std::string error_message(raycut::ErrorCode expected, const std::function<void()>& action) {
  try {
    action();
  } catch (const raycut::Error& error) {
    EXPECT_EQ(error.code(), expected) << error.what();
    return error.what();
  }
  ADD_FAILURE() << "no raycut::Error thrown";
  return "";
}

inline bool contains(const std::string& text, const std::string& part) {
  return text.find(part) != std::string::npos;
}

}  // namespace raycut_test
