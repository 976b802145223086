// raycut::system_info() (raycut::tools): what benchmark rows say they ran on.
#include <gtest/gtest.h>

#include <string>

#include "raycut/engine.hpp"
#include "raycut/tools/system_info.hpp"

namespace {

TEST(SystemInfo, DescribesTheCpuAndTheGpuWhenThereIsOne) {
  const raycut::SystemInfo info = raycut::system_info();
  EXPECT_NE(info.cpu.find(" threads)"), std::string::npos) << info.cpu;
  if (raycut::cuda_device_available()) {
    EXPECT_NE(info.gpu, "none");
    EXPECT_NE(info.cuda, "none");
  } else {
    EXPECT_EQ(info.gpu, "none");
    EXPECT_EQ(info.driver, "none");
    EXPECT_EQ(info.cuda, "none");
  }
  EXPECT_FALSE(info.optix.empty());  // a version, or "none"
}

}  // namespace
