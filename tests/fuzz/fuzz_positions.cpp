// libFuzzer target of the position readers (read_positions: CSV and extended XYZ). The first byte
// picks the format ('x': .xyz, anything else: .csv), the rest is the file. A reader may refuse a
// file only with raycut::Error; anything else (a crash, a sanitizer report, another exception,
// a hang, unbounded memory) is a bug. Built and run by run.sh.
#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "raycut/error.hpp"
#include "raycut/tools/io.hpp"

namespace {

std::string scratch_path(const char* extension) {
  const char* dir = std::getenv("RAYCUT_FUZZ_SCRATCH");
  return std::string(dir != nullptr ? dir : "/tmp") + "/raycut-fuzz-" + std::to_string(::getpid()) +
         extension;
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  static const std::string csv = scratch_path(".csv"), xyz = scratch_path(".xyz");
  const std::string& path = data[0] == 'x' ? xyz : csv;
  std::FILE* file = std::fopen(path.c_str(), "wb");
  if (file == nullptr) std::abort();
  if (size > 1 && std::fwrite(data + 1, 1, size - 1, file) != size - 1) std::abort();
  if (std::fclose(file) != 0) std::abort();
  try {
    const raycut::PointCloud cloud = raycut::read_positions(path);
    if (cloud.xyz.size() % 3 != 0) std::abort();  // whole particles only
  } catch (const raycut::Error& error) {
    if (error.code() != raycut::ErrorCode::io) std::abort();
  }
  return 0;
}
