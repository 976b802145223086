// Two particles 0.5 apart with cutoff 1: each has one neighbour.
#include <raycut/engine.hpp>

#include <cstdio>
#include <vector>

int main() {
  std::vector<float> xyz = {0, 0, 0, 0.5f, 0, 0};
  raycut::Engine engine("cell-list");
  engine.build({xyz.data(), 2, raycut::MemorySpace::host}, 1.0f);
  const auto r = engine.compute(raycut::Kernel::count);
  std::printf("counts %u %u\n", r.count[0], r.count[1]);
  return r.count == std::vector<std::uint32_t>{1, 1} ? 0 : 1;
}
