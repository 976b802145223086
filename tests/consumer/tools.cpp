// raycut::tools from the installed package: a generated cloud's lists compared with themselves,
// and the machine described (DeviceArray and system_info() live in the tools).
#include <raycut/engine.hpp>
#include <raycut/tools/compare.hpp>
#include <raycut/tools/device_array.hpp>
#include <raycut/tools/generators.hpp>
#include <raycut/tools/system_info.hpp>

#include <cstdio>
#include <vector>

// A device copy: made where there is a GPU, refused as unsupported where there is none.
bool device_array_works() {
  try {
    const raycut::DeviceArray positions(std::vector<float>{0, 0, 0, 1, 1, 1});
    return raycut::cuda_device_available() && positions.view().size == 2;
  } catch (const raycut::Error& e) {
    return !raycut::cuda_device_available() && e.code() == raycut::ErrorCode::unsupported;
  }
}

int main() {
  const raycut::PointCloud cloud = raycut::uniform_suite(4, 2);
  raycut::Engine engine("cell-list");
  engine.build({cloud.xyz.data(), cloud.size(), raycut::MemorySpace::host}, cloud.cutoff);
  const raycut::NeighbourList list = engine.neighbours();
  const raycut::NeighbourComparison same = raycut::compare_neighbours(list, list);
  const raycut::SystemInfo machine = raycut::system_info();
  const bool device = device_array_works();
  std::printf("tools: %zu points, lists equal: %d, cpu: %s, gpu: %s, device array: %d\n",
              cloud.size(), same.equal() ? 1 : 0, machine.cpu.c_str(), machine.gpu.c_str(),
              device ? 1 : 0);
  return cloud.size() == 128 && same.equal() && !machine.cpu.empty() && device ? 0 : 1;
}
