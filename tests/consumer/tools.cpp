// raycut::tools from the installed package: a generated cloud's lists compared with themselves.
#include <raycut/engine.hpp>
#include <raycut/tools/compare.hpp>
#include <raycut/tools/generators.hpp>

#include <cstdio>

int main() {
  const raycut::PointCloud cloud = raycut::uniform_suite(4, 2);
  raycut::Engine engine("cell-list");
  engine.build({cloud.xyz.data(), cloud.size(), raycut::MemorySpace::host}, cloud.cutoff);
  const raycut::NeighbourList list = engine.neighbours();
  const raycut::NeighbourComparison same = raycut::compare_neighbours(list, list);
  std::printf("tools: %zu points, lists equal: %d\n", cloud.size(), same.equal() ? 1 : 0);
  return cloud.size() == 128 && same.equal() ? 0 : 1;
}
