// The raycut engine: choose a method, build it over positions, then compute a fused pair kernel
// or a neighbour list. Host-only header: no CUDA or OptiX types.
//
//   raycut::Engine engine("auto");
//   engine.build({xyz.data(), n, raycut::MemorySpace::host}, cutoff);
//   raycut::Results r = engine.compute(raycut::Kernel::count);
//   raycut::NeighbourList list = engine.neighbours();
#pragma once

#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "raycut/error.hpp"
#include "raycut/kernels.hpp"

namespace raycut {

enum class MemorySpace { host, device };

// (N,3) float32 positions, row-major (x0 y0 z0 x1 y1 z1 ...), on the host or the CUDA device.
// The engine does not keep the pointer beyond build().
struct PositionsView {
  const float* xyz = nullptr;
  std::size_t size = 0;  // N, the number of particles
  MemorySpace space = MemorySpace::host;
};

// Per-target results on the host; a vector is empty when the kernel does not produce it.
struct Results {
  std::vector<std::uint32_t> count;  // count kernel
  std::vector<float> energy;         // lj, smooth
  std::vector<float> force;          // smooth: 3 per target (fx fy fz)
};

// The results of the last run() where the method keeps them (Engine::space()), without a copy:
// valid until the next build(), update() or run(). Null where the kernel does not produce it.
struct ResultsView {
  const std::uint32_t* count = nullptr;
  const float* energy = nullptr;
  const float* force = nullptr;
  MemorySpace space = MemorySpace::host;
};

// Full neighbour list in CSR form: the in-range sources of target i are
// indices[offsets[i] .. offsets[i+1]); their order within a row is unspecified.
struct NeighbourList {
  std::vector<std::uint64_t> offsets;  // N + 1 entries
  std::vector<std::uint32_t> indices;
};

// Wall-clock milliseconds of the last build()/update() and run(), each phase synchronised.
// device_* are the CUDA-event times of the same phases for GPU methods, negative for CPU
// methods. refit: the last update() refitted the structure instead of rebuilding it.
struct Timings {
  double build_ms = 0, compute_ms = 0;
  double device_build_ms = -1, device_compute_ms = -1;
  bool refit = false;
};

// How update() treats moved particles. skin = 0: rebuild every time (what the paper does).
// skin > 0: methods that can (the OptiX methods) refit their acceleration structure to the new
// positions (always exact: the primitives move with the particles) while no particle has moved
// more than skin / 2 since the last full build, and rebuild beyond that, when the refitted
// tree has lost too much quality.
struct UpdatePolicy {
  float skin = 0;
};

struct MethodDescription {
  std::string name;
  std::string summary;
  bool available = false;  // built in, and its hardware is present
  std::string why_unavailable;
};

// A copy of a host float array in CUDA device memory, for callers without CUDA code of their own
// (the benchmark, where positions start on the device; device-side kernel inputs). Throws
// Error(unsupported) without CUDA and Error(out_of_memory) when it does not fit.
class DeviceArray {
 public:
  explicit DeviceArray(const std::vector<float>& values);
  ~DeviceArray();
  DeviceArray(DeviceArray&&) noexcept;
  DeviceArray& operator=(DeviceArray&&) noexcept;
  const float* data() const { return data_; }
  float* data() { return data_; }
  std::size_t size() const { return size_; }
  // The array as (N,3) positions.
  PositionsView view() const { return {data_, size_ / 3, MemorySpace::device}; }

 private:
  float* data_ = nullptr;
  std::size_t size_ = 0;  // floats
};

// What the results were measured on: for benchmark rows.
struct SystemInfo {
  std::string gpu;     // device name, or "none"
  std::string driver;  // NVIDIA driver version, or "none"
  std::string cuda;    // CUDA runtime version, e.g. "13.0", or "none"
  std::string optix;   // OptiX headers version built against, or "none"
  std::string cpu;     // CPU model and thread count
};
SystemInfo system_info();

// Every method raycut knows, available or not, in a stable order.
std::vector<MethodDescription> list_methods();
// What "auto" picks on this machine.
std::string auto_method();
// True when a CUDA device is usable in this process.
bool cuda_device_available();

namespace detail {
class Method;
}

class Engine {
 public:
  // `method` is a name from list_methods() or "auto". Throws Error(invalid_argument) for an
  // unknown name, Error(unsupported) for a method not available here.
  explicit Engine(std::string_view method = "auto");
  ~Engine();
  Engine(Engine&&) noexcept;
  Engine& operator=(Engine&&) noexcept;

  const std::string& method() const { return method_; }
  // Where the method works: positions given there avoid a copy (and an untimed transfer).
  MemorySpace space() const;

  // Validates (finite coordinates, cutoff finite and > 0) and builds the method's structure.
  // Throws Error with the first bad index or the bad value, before any device work.
  void build(PositionsView positions, float cutoff);

  // New positions of the same N particles, cutoff unchanged: refit or rebuild per the policy.
  void update(PositionsView positions);
  void set_update_policy(const UpdatePolicy& policy);

  // Computes `kernel` for every target and keeps the results in the method's memory.
  void run(Kernel kernel, const KernelOptions& options = {});
  // Copies the results of the last run() to the host.
  Results results() const;
  // The results of the last run() in place (no copy): what an integrator on the device reads.
  ResultsView results_view() const;
  // run() then results().
  Results compute(Kernel kernel, const KernelOptions& options = {});

  // The full CSR neighbour list of the built positions.
  NeighbourList neighbours();

  const Timings& last_timings() const { return timings_; }
  std::size_t size() const { return size_; }
  float cutoff() const { return cutoff_; }

 private:
  template <class F>
  void with_positions_in_method_space(const PositionsView& positions, F&& f);

  std::string method_;
  std::unique_ptr<detail::Method> impl_;
  std::size_t size_ = 0;
  float cutoff_ = 0;
  bool built_ = false;
  Kernel last_kernel_ = Kernel::count;
  bool has_run_ = false;
  Timings timings_;
};

}  // namespace raycut
