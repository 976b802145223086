// The composition root: the list of methods this build knows, in the order users see them, and
// the backends' services handed to core (core/device_services.hpp). The one place that knows
// which backends are compiled in (RAYCUT_HAVE_CUDA, RAYCUT_HAVE_OPTIX): core, cpu and the
// backends below it never ask (scripts/check_layers.py checks what each layer includes).
#include <string>

#include "core/device_services.hpp"
#include "core/method.hpp"

#if defined(RAYCUT_HAVE_CUDA)
#include "cuda/methods.hpp"
#include "cuda/runtime.hpp"
#endif
#if defined(RAYCUT_HAVE_OPTIX)
#include "optix/methods.hpp"
#endif

namespace raycut::detail {
namespace {

std::string always_available() {
  return {};
}

std::string cuda_status() {
#if defined(RAYCUT_HAVE_CUDA)
  return cuda::device_available() ? std::string() : "no CUDA device found";
#else
  return "raycut was built without CUDA (nvcc not found at configure time)";
#endif
}

std::string optix_status() {
#if defined(RAYCUT_HAVE_OPTIX)
  if (std::string why = cuda_status(); !why.empty()) return why;
  return optix::unavailable_reason();
#else
  return "raycut was built without OptiX (set OptiX_ROOT to the OptiX SDK headers)";
#endif
}

#if defined(RAYCUT_HAVE_CUDA)
#define RAYCUT_CUDA_FACTORY(f) f
#else
#define RAYCUT_CUDA_FACTORY(f) nullptr
#endif
#if defined(RAYCUT_HAVE_OPTIX)
#define RAYCUT_OPTIX_FACTORY(f) f
#else
#define RAYCUT_OPTIX_FACTORY(f) nullptr
#endif

}  // namespace

const std::vector<MethodEntry>& method_registry() {
  static const std::vector<MethodEntry> registry = {
      {"brute-force", "CPU, all pairs: the reference oracle", all_capabilities, always_available,
       make_brute_force_cpu},
      {"cell-list", "CPU, compact cell list (OpenMP), memory O(N)", all_capabilities,
       always_available, make_cell_list_cpu},
      {"brute-force-gpu", "CUDA, all pairs: the oracle on the GPU", all_capabilities, cuda_status,
       RAYCUT_CUDA_FACTORY(cuda::make_brute_force)},
      {"optix-spheres", "OptiX, built-in spheres + 3 axis rays (the paper's method 2, exact)",
       no_capabilities, optix_status, RAYCUT_OPTIX_FACTORY(optix::make_spheres)},
      {"optix-triangles", "OptiX, double squares of triangles + 4 rays (method 3, exact)",
       no_capabilities, optix_status, RAYCUT_OPTIX_FACTORY(optix::make_triangles)},
      {"optix-aabb", "OptiX, custom AABBs + zero-length rays (the paper's method 4)",
       no_capabilities, optix_status, RAYCUT_OPTIX_FACTORY([] { return optix::make_aabb(false); })},
      {"optix-aabb-sorted", "OptiX, custom AABBs on Morton-sorted particles", no_capabilities,
       optix_status, RAYCUT_OPTIX_FACTORY([] { return optix::make_aabb(true); })},
      {"optix-aabb-fused", "OptiX, custom AABBs, work in the intersection program (as the paper)",
       no_capabilities, optix_status,
       RAYCUT_OPTIX_FACTORY([] { return optix::make_aabb(false, true); })},
      {"grid", "CUDA, sorted grid of cells, memory O(N): the fastest general method",
       all_capabilities, cuda_status, RAYCUT_CUDA_FACTORY(cuda::make_grid)},
      {"grid-paper", "CUDA, the paper's dense grid, for comparison (memory grows with the box)",
       functors_only, cuda_status, RAYCUT_CUDA_FACTORY(cuda::make_grid_paper)},
  };
  return registry;
}

const DeviceServices* device_services() {
#if defined(RAYCUT_HAVE_CUDA)
  return &cuda::device_services();
#else
  return nullptr;
#endif
}

std::string optix_headers_version() {
#if defined(RAYCUT_OPTIX_VERSION)
  return std::to_string(RAYCUT_OPTIX_VERSION / 10000) + "." +
         std::to_string(RAYCUT_OPTIX_VERSION % 10000 / 100) + "." +
         std::to_string(RAYCUT_OPTIX_VERSION % 100);
#else
  return {};
#endif
}

}  // namespace raycut::detail
