// The internal interface every interaction method implements: a build, and the one pair pass
// that runs every functor (kernels, list counting and filling, the caller's own). Everything
// else (validation, timing, N = 0, host/device transfers of results) lives in the Engine.
#pragma once

#include <cstddef>
#include <cstdint>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "core/list_storage.hpp"
#include "raycut/detail/pair_pass.hpp"
#include "raycut/detail/row_pass.hpp"
#include "raycut/engine.hpp"

namespace raycut::detail {

// What a CPU method allocates per point when it builds: the cell list's keys, order and cells
// and its sort's scratch (~70 B), more than brute force's copy of the positions (12 B).
constexpr double host_build_bytes_per_point = 80;

// Where the spare slots of a reused plan park (Engine::set_reuse_plan): the sheet x = `x`, y and z
// within [lo, hi], that no real point's search reaches. The slots are spread over it, a few a
// cell: one cell holding them all would cost the grid's table build a rank per pair of them.
struct ParkingPlace {
  float x = 0;
  float lo[2] = {0, 0}, hi[2] = {0, 0};  // y, z
};

// What a method builds over when there are images, batches or query points (the engine makes
// it, src/core/images.hpp): points [0, targets) are the targets; every point is a candidate
// source, mapped by `images` to the caller's source and shift (images.exact: what decides the
// pairs of the float band in double). Pointers in the method's memory space, owned by the engine
// and valid until the next build.
struct Points {
  const float* xyz = nullptr;  // (size, 3)
  std::size_t size = 0;
  std::size_t targets = 0;
  ImageTables images;
  const std::uint32_t* system = nullptr;  // per point; null: one system
  std::uint32_t systems = 1;
  // Engine::set_reuse_plan. `record`: the later builds will reuse this one's plan, sized for
  // `planned_size` points, with a parking place (Method::parking) for the slots they leave
  // empty. `misfit`: this build reuses the last recorded plan; its points past the real ones
  // are parked, and what no longer fits is reported in this device word (0: it fits; else a
  // StaticPairs count code), which the method's static lists report as their count.
  struct PlanReuse {
    bool record = false;
    std::size_t planned_size = 0;
    int* misfit = nullptr;
  } reuse;
  // n plain particles: every point a target and its own source, one system.
  static Points plain(const float* xyz, std::size_t n) {
    Points p;
    p.xyz = xyz;
    p.size = p.targets = n;
    return p;
  }
};

class Method {
 public:
  virtual ~Method() = default;

  // Where the method wants its positions. The engine moves them there before build().
  virtual MemorySpace space() const = 0;
  // The CUDA stream GPU methods queue their work on (a cudaStream_t; null: the default).
  virtual void set_stream(void*) {}

  // Build over n >= 1 validated positions (in space()), cutoff validated. The pointer is
  // valid only during the call: copy what you need.
  virtual void build(const float* xyz, std::size_t n, float cutoff) = 0;

  // Build over points with images, batches or queries. Methods that cannot say so
  // (supports_points() names why) and keep the default.
  virtual void build_points(const Points&, float) {
    throw Error(ErrorCode::unsupported,
                "this method does not take periodic boxes, batches or "
                "query points");
  }
  // Empty when build_points() works; otherwise why not, for the engine's message.
  virtual std::string points_unsupported() const {
    return "its traversal has no images, batches or query points (docs/methods.md)";
  }
  // Engine::set_reuse_plan: whether build_points() takes Points::reuse, and after a recording
  // build, where in its grid the spare slots park (false: nowhere).
  virtual bool reuses_plans() const { return false; }
  virtual bool parking(ParkingPlace&) const { return false; }

  // New positions of the same n particles. Returns true when the structure was refitted;
  // the default rebuilds.
  virtual bool update(const float* xyz, std::size_t n, float cutoff) {
    build(xyz, n, cutoff);
    return false;
  }
  virtual void set_update_policy(const UpdatePolicy&) {}

  // Compute `kernel` for every target; keep the results until the next compute()/build().
  // A compute that throws leaves no results (results() then throws).
  virtual void compute(Kernel kernel, const KernelOptions& options) = 0;
  virtual Results results() const = 0;
  virtual ResultsView results_view() const = 0;
  // The results moved out (Engine::take_results); the method then holds none.
  virtual OwnedResults take_results() = 0;

  // Lists, into storage of the method's memory space (made by the method).
  virtual std::unique_ptr<ListStorage> make_list_storage() const = 0;
  virtual std::unique_ptr<PaddedStorage> make_padded_storage() const = 0;
  virtual void neighbours(ListStorage& list, const ListOptions& options) = 0;
  virtual void padded_neighbours(PaddedStorage& list, std::uint32_t k, bool half, bool shifts) = 0;
  // Each row's K nearest, nearest first (PaddedOptions::nearest): CPU methods (the engine
  // refuses it for the others before calling).
  virtual void padded_nearest(PaddedStorage& list, std::uint32_t k, bool half, bool shifts) {
    (void)list, (void)k, (void)half, (void)shifts;
    throw Error(ErrorCode::unsupported, "this method has no nearest-K padded list");
  }
  // A list of n targets into a static capacity (Engine::neighbours(StaticPairs)): no read-back;
  // n = 0 writes the count and the padding only.
  virtual void static_neighbours(const StaticPairs& out, const ListOptions& options,
                                 std::size_t n) = 0;

  // The traversal a caller's functor runs through (kind none: the method cannot run one).
  virtual PairPass pair_pass() const { return {}; }
  // A built-in kernel over mapped rows (raycut/detail/row_pass.hpp), written by mapped row to
  // `out`, in the method's own loop: the CPU methods (the distributed engine's local passes).
  virtual void compute_rows(Kernel, const KernelOptions&, const RowMap&, const KernelOutputs&) {
    throw Error(ErrorCode::unsupported, "this method runs no kernel over mapped rows");
  }
  // A full neighbour list's count and fill passes over mapped rows, the same way: counts and
  // offsets by mapped row, sources and shifts mapped (RowPass).
  virtual void list_rows(const RowMap&, const ListCount&) {
    throw Error(ErrorCode::unsupported, "this method runs no list over mapped rows");
  }
  virtual void list_rows(const RowMap&, const ListFill&) {
    throw Error(ErrorCode::unsupported, "this method runs no list over mapped rows");
  }

  // Waits for the work queued by build()/compute() (GPU methods); CPU methods are synchronous.
  virtual void synchronize() {}
  // CUDA-event milliseconds of the last build()/compute(); negative when not measured.
  virtual double device_build_ms() const { return -1; }
  virtual double device_compute_ms() const { return -1; }
};

// What a traversal can do (MethodCapabilities), for the registry's entries: the CPU methods and
// the GPU grid and brute force take every Systems form and run functors; the OptiX pipelines
// neither; the paper's grid runs functors on plain particles only.
inline constexpr MethodCapabilities all_capabilities{true, true, true};
inline constexpr MethodCapabilities no_capabilities{false, false, false};
inline constexpr MethodCapabilities functors_only{false, false, true};

struct MethodEntry {
  std::string name;
  std::string summary;
  MethodCapabilities capabilities;
  // Empty when available; otherwise why not (not built, no GPU, no OptiX).
  std::function<std::string()> why_unavailable;
  std::function<std::unique_ptr<Method>()> make;
};

// All methods of this build, in the order list_methods() reports them (the composition root,
// src/backends/registry.cpp).
const std::vector<MethodEntry>& method_registry();

// Factories, defined by each backend (only those compiled in are referenced).
std::unique_ptr<Method> make_brute_force_cpu();
std::unique_ptr<Method> make_cell_list_cpu();

}  // namespace raycut::detail
