// PyTorch operators over the raycut engine: torch.ops.raycut.neighbor_list and
// torch.ops.raycut.radius, registered with the dispatcher (TORCH_LIBRARY) so that the same call
// runs in eager mode, TorchScript, torch.compile, torch.export and AOTInductor packages. Their
// fake (meta) implementations, which give torch.compile and torch.export the output shapes, are
// registered in Python (python/pyraycut/_torch.py).
//
// The ops return integer pairs only, (i, j, S, count): distances and vectors are computed in
// PyTorch from them and the caller's positions and cell, so that autograd (to any order) never
// reaches the op. With max_pairs the outputs have that static size (padding: i = j = the number
// of points, S = 0), otherwise the exact pair count.
//
// Kernels: the CPU cell list; with RAYCUT_TORCH_CUDA (raycut built with CUDA, torch with CUDA)
// also the CUDA grid on the tensors' device and current stream, and for neighbor_list with
// max_pairs on small systems (raycut::prefer_small_systems) the stream-ordered pass of
// raycut/device_pairs.hpp, which never waits on the host (a CUDA graph captures it).
//
// Built as its own shared library (pyraycut/_torch_ops.so), against the classic C++ API of the
// torch it is built with: docs/python.md says why.
#include <ATen/ATen.h>
#include <torch/library.h>

#ifdef RAYCUT_TORCH_CUDA
#include <c10/cuda/CUDACachingAllocator.h>
#include <c10/cuda/CUDAGraphsC10Utils.h>
#include <c10/cuda/CUDAGuard.h>
#include <c10/cuda/CUDAStream.h>

#include "device.hpp"
#include "raycut/context.hpp"
#include "raycut/device_pairs.hpp"
#endif

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <tuple>
#include <vector>

#include "idle_lists.hpp"
#include "pair_outputs.hpp"
#include "raycut/engine.hpp"
#include "raycut/error.hpp"

namespace {

using Pairs = std::tuple<at::Tensor, at::Tensor, at::Tensor, at::Tensor>;

// The library's errors as PyTorch's: ValueError for bad input, NotImplementedError for what this
// build cannot do, torch.OutOfMemoryError when it does not fit, RuntimeError otherwise.
[[noreturn]] void rethrow(const raycut::Error& e) {
  switch (e.code()) {
    case raycut::ErrorCode::invalid_argument:
    case raycut::ErrorCode::invalid_input:
      TORCH_CHECK_VALUE(false, e.what());
    case raycut::ErrorCode::unsupported:
      TORCH_CHECK_NOT_IMPLEMENTED(false, e.what());
    case raycut::ErrorCode::out_of_memory:
      TORCH_CHECK_WITH(OutOfMemoryError, false, e.what());
    default:
      TORCH_CHECK(false, e.what());
  }
}

// (N, 3) float32 or float64 points as the engine searches them: float32, C-contiguous, on their
// device. float64 CPU positions also go to the engine as they are (run's `wide`), which decides
// in double what the float rounding could (docs/limits.md, "float64 positions").
void check_points(const at::Tensor& x, const char* name) {
  TORCH_CHECK_VALUE(x.dim() == 2 && x.size(1) == 3, name, " must have shape (N, 3), got ",
                    x.sizes());
  TORCH_CHECK_VALUE(x.scalar_type() == at::kFloat || x.scalar_type() == at::kDouble, name,
                    " must be float32 or float64, got ", x.scalar_type());
}
at::Tensor search_points(const at::Tensor& x, const char* name) {
  check_points(x, name);
  return x.to(at::kFloat).contiguous();
}

// The shape and dtype checks of cell, pbc and batch: host metadata only, never their values.
void check_cell(const at::Tensor& c) {
  TORCH_CHECK_VALUE(c.is_floating_point(), "cell must be float32 or float64, got ",
                    c.scalar_type());
  TORCH_CHECK_VALUE((c.dim() == 2 || c.dim() == 3) && c.size(-1) == 3 && c.size(-2) == 3,
                    "cell must have shape (3, 3) (rows: lattice vectors a, b, c) or (B, 3, 3) "
                    "(one per system of a batch), got ",
                    c.sizes());
}
void check_pbc_type(const at::Tensor& pbc) {
  TORCH_CHECK_VALUE(pbc.scalar_type() == at::kBool, "pbc must be bool, got ", pbc.scalar_type());
}
void check_pbc(const at::Tensor& pbc) {
  check_pbc_type(pbc);
  TORCH_CHECK_VALUE((pbc.dim() == 1 || pbc.dim() == 2) && pbc.size(-1) == 3,
                    "pbc must have shape (3,) or (B, 3) (one row per system), got ", pbc.sizes());
}
void check_system_counts(std::int64_t cells, std::int64_t flags) {
  const std::int64_t count = std::max(cells, flags);
  TORCH_CHECK_VALUE((cells == count || cells == 1) && (flags == count || flags == 1), "cell gives ",
                    cells, " systems but pbc ", flags);
}
void check_batch(const at::Tensor& b, std::int64_t n, const char* name) {
  TORCH_CHECK_VALUE(!b.is_floating_point() && !b.is_complex() && b.scalar_type() != at::kBool, name,
                    " must be integers (the system of each particle), got ", b.scalar_type());
  TORCH_CHECK_VALUE(b.dim() == 1 && b.size(0) == n, name,
                    " must have one system index per particle, shape (", n, ",), got shape ",
                    b.sizes());
}
void check_systems_are_told(std::int64_t systems, bool has_index, const char* index_name) {
  TORCH_CHECK_VALUE(systems <= 1 || has_index, "cell/pbc give ", systems,
                    " systems (shape (B, 3, 3) / (B, 3)) but no ", index_name,
                    " says which particles belong to which");
}
void check_max_pairs(std::int64_t max_pairs) {
  TORCH_CHECK_VALUE(max_pairs >= 0, "max_pairs must be >= 0 (the static number of pairs), got ",
                    max_pairs);
}

// cell (3, 3) or (B, 3, 3) and pbc (3,) or (B, 3) as raycut boxes: one for every system, or
// one per system. None: open. A cell without pbc repeats along all three rows.
std::vector<raycut::Box> boxes_of(const std::optional<at::Tensor>& cell,
                                  const std::optional<at::Tensor>& pbc) {
  if (!cell) {
    if (pbc) {
      check_pbc_type(*pbc);
      TORCH_CHECK_VALUE(!pbc->any().item<bool>(),
                        "pbc without a cell: periodic axes need their lattice vectors (pass "
                        "cell, rows a, b, c)");
    }
    return {};
  }
  const at::Tensor& c = *cell;
  check_cell(c);
  // To the host first: a device cell costs one copy and no conversion kernel there.
  const at::Tensor cells = c.reshape({-1, 3, 3}).cpu().to(at::kDouble).contiguous();
  at::Tensor flags;
  if (pbc) {
    check_pbc(*pbc);
    flags = pbc->reshape({-1, 3}).cpu().contiguous();
  } else {
    flags = at::ones({1, 3}, at::kBool);
  }
  check_system_counts(cells.size(0), flags.size(0));
  const std::int64_t count = std::max(cells.size(0), flags.size(0));
  const double* cell_data = cells.data_ptr<double>();
  const bool* flag_data = flags.data_ptr<bool>();
  std::vector<raycut::Box> boxes(static_cast<std::size_t>(count));
  for (std::int64_t b = 0; b < count; ++b) {
    const double* rows = cell_data + (cells.size(0) == 1 ? 0 : 9 * b);
    const bool* repeat = flag_data + (flags.size(0) == 1 ? 0 : 3 * b);
    for (int r = 0; r < 3; ++r) {
      boxes[b].pbc[r] = repeat[r];
      for (int k = 0; k < 3; ++k) boxes[b].cell[r][k] = rows[3 * r + k];
    }
  }
  return boxes;
}

// A system index (torch_cluster's batch): (n,) integers, sorted, non-negative. int64 on the
// host, validated; an empty tensor for None.
at::Tensor system_index(const std::optional<at::Tensor>& batch, std::int64_t n, const char* name) {
  if (!batch) return at::Tensor();
  const at::Tensor& b = *batch;
  check_batch(b, n, name);
  at::Tensor index = b.to(at::kLong).cpu().contiguous();
  const std::int64_t* v = index.data_ptr<std::int64_t>();
  for (std::int64_t k = 0; k < n; ++k) {
    TORCH_CHECK_VALUE(v[k] >= 0, name, " holds a negative system index (", v[k], " at ", k, ")");
    TORCH_CHECK_VALUE(k + 1 == n || v[k] <= v[k + 1], name,
                      " must be sorted (each system's particles contiguous, systems in order): ",
                      name, "[", k, "] = ", v[k], " > ", name, "[", k + 1, "] = ", v[k + 1]);
  }
  return index;
}

// offsets[s] = the number of entries of `index` below system s (systems + 1 of them); all in
// system 0 when `index` is empty (None).
std::vector<std::uint64_t> offsets_of(const at::Tensor& index, std::int64_t n,
                                      const std::vector<std::int64_t>& systems_of_value) {
  std::vector<std::uint64_t> offsets(systems_of_value.size() + 1, 0);
  if (!index.defined()) {
    std::fill(offsets.begin() + 1, offsets.end(), static_cast<std::uint64_t>(n));
    return offsets;
  }
  const std::int64_t* v = index.data_ptr<std::int64_t>();
  // systems_of_value: the sorted system numbers in use; entries count towards theirs.
  std::size_t s = 0;
  for (std::int64_t k = 0; k < n; ++k) {
    while (systems_of_value[s] < v[k]) ++s;
    ++offsets[s + 1];
  }
  for (std::size_t t = 1; t < offsets.size(); ++t) offsets[t] += offsets[t - 1];
  return offsets;
}

// raycut::Systems of boxes and up to two system indices (sources, and queries when `queries`
// holds points). Per-system boxes: the indices number the boxes. One box for every system: the
// numbers only group, so the systems in use are renumbered densely (a sparse index such as
// [0, 10**9] costs no empty systems).
raycut::Systems systems_of(std::vector<raycut::Box> boxes, const at::Tensor& index, std::int64_t n,
                           const at::Tensor& query_index, std::int64_t m, bool with_queries,
                           const char* index_name) {
  raycut::Systems systems;
  const bool per_system = boxes.size() > 1;
  if (!index.defined() && !query_index.defined()) {
    check_systems_are_told(static_cast<std::int64_t>(boxes.size()), false, index_name);
    if (!boxes.empty()) systems.box = boxes[0];
    return systems;
  }
  std::vector<std::int64_t> used;  // the system numbers, sorted
  if (per_system) {
    const auto b = static_cast<std::int64_t>(boxes.size());
    for (const at::Tensor* t : {&index, &query_index})
      if (t->defined() && t->numel() > 0) {
        const std::int64_t last = t->data_ptr<std::int64_t>()[t->numel() - 1];
        TORCH_CHECK_VALUE(last < b, "the batch has system index ", last, " but cell/pbc give ", b,
                          " systems");
      }
    used.resize(boxes.size());
    for (std::int64_t s = 0; s < b; ++s) used[s] = s;
    systems.boxes = std::move(boxes);
  } else {
    for (const at::Tensor* t : {&index, &query_index})
      if (t->defined()) {
        const std::int64_t* v = t->data_ptr<std::int64_t>();
        for (std::int64_t k = 0; k < t->numel(); ++k)
          if (k == 0 || v[k] != v[k - 1]) used.push_back(v[k]);
      }
    // An index left out: every point of that set is in system 0 (torch_cluster's convention).
    if (!index.defined() || (with_queries && !query_index.defined())) used.push_back(0);
    std::sort(used.begin(), used.end());
    used.erase(std::unique(used.begin(), used.end()), used.end());
    if (used.empty()) used.push_back(0);
    if (!boxes.empty()) systems.box = boxes[0];
  }
  systems.offsets = offsets_of(index, n, used);
  if (with_queries) systems.query_offsets = offsets_of(query_index, m, used);
  return systems;
}

// One engine per thread and device, reused from call to call (its structure buffers only grow):
// the CPU cell list, or the CUDA grid on each CUDA device. Lists are buffers of their own per
// call: on the CPU recycled ones (idle_lists(), the outputs wrap them), on CUDA fresh ones from
// raycut's stream-ordered pool, so that a copy of the last call's pairs still queued on another
// stream never reads a refilled buffer.
struct Work {
  // Untimed: timing a GPU build waits for it, and an operator call never reads the times. Its
  // builds reuse the last plan (on CUDA, a build reads nothing back while the plan fits; a
  // static list reports one that no longer does as count_plan_outgrown; every call's positions
  // outlive the call's own results).
  explicit Work(const char* method) : engine(method) { engine.set_timed(false); }
  // The engines reuse plans and static lists keep a device cell's boxes (CallBoxes), unless the
  // environment sets RAYCUT_REUSE_PLAN=0 (read at each call): then every build plans and waits.
  static bool reuse_plans() {
    const char* v = std::getenv("RAYCUT_REUSE_PLAN");
    return v == nullptr || !(v[0] == '0' && v[1] == '\0');
  }
  raycut::Engine engine;

#ifdef RAYCUT_TORCH_CUDA
  // A static list's device cell (and pbc), so that a call need not copy it to the host while it
  // is the one the last copy was made from: the boxes of that copy are taken again, and the
  // device compares the cell (and a device pbc) with copies kept on the device (a kernel each,
  // after the list); a different one makes the count count_plan_outgrown and the next call
  // copies them again.
  struct CellWatch {
    at::Tensor seen;        // the cell the boxes were made from, on the device
    at::Tensor seen_pbc;    // its pbc on the device (a device pbc is compared with it), or none
    at::Tensor pbc_values;  // the same on the host (a host pbc is compared with it)
    std::vector<raycut::Box> boxes;
    raycut_py::ChangeFlag changed;
    // Whether `boxes` are those of this cell and pbc as far as the host can tell without reading
    // the device: the same shapes, dtypes and device, a host pbc equal, and no comparison found
    // a change (a change found is remembered: the cell is copied again). The pbc may come on
    // the host in one call and on the device in another (the Python wrapper sends it to the
    // device under capture).
    bool holds(const at::Tensor& cell, const std::optional<at::Tensor>& pbc, void* stream) {
      if (changed.raised(stream)) seen = at::Tensor();
      const bool same_pbc = pbc ? seen_pbc.defined() && seen_pbc.sizes() == pbc->sizes() &&
                                      seen_pbc.scalar_type() == pbc->scalar_type() &&
                                      (pbc->is_cuda() ? pbc->device() == seen_pbc.device()
                                                      : at::equal(pbc_values, *pbc))
                                : !seen_pbc.defined();
      return seen.defined() && seen.sizes() == cell.sizes() &&
             seen.scalar_type() == cell.scalar_type() && seen.device() == cell.device() && same_pbc;
    }
  } cell_watch;
#endif

  // On CUDA, the last call's list again while the stream is the same (the copies out of it were
  // queued there before the next fill): no allocation per call, and no free, which waits for the
  // whole device. It keeps the largest list's memory until the thread ends, as the engine keeps
  // its own.
  std::shared_ptr<raycut::NeighbourListBuffer> device_list() {
    if (!list_ || list_stream_ != engine.stream()) {
      list_ = std::make_shared<raycut::NeighbourListBuffer>();
      list_stream_ = engine.stream();
    }
    return list_;
  }

 private:
  std::shared_ptr<raycut::NeighbourListBuffer> list_;
  void* list_stream_ = nullptr;
};
Work& work_for(const at::Device& device) {
  if (device.is_cpu()) {
    thread_local Work host("cell-list");
    return host;
  }
  TORCH_CHECK_NOT_IMPLEMENTED(device.is_cuda(), "raycut's operators run on the CPU and CUDA, not ",
                              device);
  thread_local std::map<int, std::unique_ptr<Work>> per_device;
  std::unique_ptr<Work>& work = per_device[device.index()];
  if (!work) {
    try {
      work = std::make_unique<Work>("grid");
    } catch (const raycut::Error& e) {
      rethrow(e);
    }
  }
  return *work;
}

// For the length of a call: `device` current (first: a CUDA engine is made on its own device),
// its engine, and on CUDA torch's current stream as the engine's.
class OnDevice {
 public:
  explicit OnDevice(const at::Device& device) : guard_(guarded(device)), work(work_for(device)) {
#ifdef RAYCUT_TORCH_CUDA
    if (device.is_cuda())
      work.engine.set_stream(c10::cuda::getCurrentCUDAStream(device.index()).stream());
#endif
  }

 private:
#ifdef RAYCUT_TORCH_CUDA
  static std::optional<c10::cuda::CUDAGuard> guarded(const at::Device& device) {
    if (device.is_cuda()) return std::optional<c10::cuda::CUDAGuard>(std::in_place, device);
    return std::nullopt;
  }
  std::optional<c10::cuda::CUDAGuard> guard_;
#else
  static bool guarded(const at::Device&) {
    return false;
  }
  bool guard_;
#endif

 public:
  Work& work;
};

// The list's pairs as (i, j, S, count) tensors on `device`: exactly its pairs, or `max_pairs`
// entries with padding (i = pad_i, j = pad_j, S = 0) after the pairs (cut past max_pairs: count
// says so). Device lists are copied on the current stream, the one the engine worked on.
Pairs pair_tensors(const raycut::NeighbourListBuffer& list, std::optional<std::int64_t> max_pairs,
                   std::int64_t pad_i, std::int64_t pad_j, const at::Device& device) {
  const auto found = static_cast<std::int64_t>(list.pairs());
  std::int64_t size = found;
  if (max_pairs) {
    check_max_pairs(*max_pairs);
    size = *max_pairs;
  }
  const at::Tensor count = at::scalar_tensor(found, at::kLong);
  if (device.is_cpu()) {
    at::Tensor i = at::empty({size}, at::kLong);
    at::Tensor j = at::empty({size}, at::kLong);
    at::Tensor shifts = at::empty({size, 3}, at::kInt);
    raycut_py::write_pairs<std::int64_t>(list, static_cast<std::uint64_t>(size),
                                         i.data_ptr<std::int64_t>(), j.data_ptr<std::int64_t>(),
                                         shifts.data_ptr<std::int32_t>(), pad_i, pad_j);
    return {i, j, shifts, count};
  }
  const auto on_device = at::TensorOptions().device(device);
  const std::int64_t kept = std::min(found, size);
  at::Tensor i = at::empty({size}, on_device.dtype(at::kLong));
  at::Tensor j = at::empty({size}, on_device.dtype(at::kLong));
  at::Tensor shifts = at::empty({size, 3}, on_device.dtype(at::kInt));
  if (kept > 0) {
    auto wrap = [&](const void* data, at::IntArrayRef shape, at::ScalarType type) {
      return at::from_blob(const_cast<void*>(data), shape, on_device.dtype(type));
    };
    i.narrow(0, 0, kept).copy_(wrap(list.rows(), {kept}, at::kLong));
    j.narrow(0, 0, kept).copy_(wrap(list.columns(), {kept}, at::kLong));
    shifts.narrow(0, 0, kept).copy_(wrap(list.shifts(), {kept, 3}, at::kInt));
  }
  if (kept < size) {  // padding past the pairs only
    i.narrow(0, kept, size - kept).fill_(pad_i);
    j.narrow(0, kept, size - kept).fill_(pad_j);
    shifts.narrow(0, kept, size - kept).zero_();
  }
  return {i, j, shifts, count.to(device)};
}

// A host list's pairs as (i, j, S, count) tensors over its own memory, no copy: the list goes
// back to raycut_py::idle_lists() when the last of them dies.
Pairs wrapped_pairs(const std::shared_ptr<raycut::NeighbourListBuffer>& list) {
  const auto found = static_cast<std::int64_t>(list->pairs());
  const at::Tensor count = at::scalar_tensor(found, at::kLong);
  if (found == 0)
    return {at::empty({0}, at::kLong), at::empty({0}, at::kLong), at::empty({0, 3}, at::kInt),
            count};
  const auto wrap = [&](const void* data, at::IntArrayRef shape, at::ScalarType type) {
    return at::from_blob(
        const_cast<void*>(data), shape, [owner = list](void*) mutable { owner.reset(); },
        at::TensorOptions().dtype(type));
  };
  return {wrap(list->rows(), {found}, at::kLong), wrap(list->columns(), {found}, at::kLong),
          wrap(list->shifts(), {found, 3}, at::kInt), count};
}

// Builds the engine of `x`'s device over x (and `systems`) and fills a COO list with shifts:
// on the CPU in place, on CUDA on the current device and stream. `wide`: the float64 CPU
// positions x was rounded from (undefined otherwise).
Pairs run(const at::Tensor& x, double cutoff, const raycut::Systems& systems, bool half,
          std::optional<std::int64_t> max_pairs, std::int64_t pad_i, std::int64_t pad_j,
          const at::Tensor& wide = at::Tensor()) {
  const at::Device device = x.device();
  const OnDevice on(device);
  Work& work = on.work;
  work.engine.set_reuse_plan(Work::reuse_plans());
  std::shared_ptr<raycut::NeighbourListBuffer> list;  // not for a static list (a graph may hold it)
  const auto space = device.is_cpu() ? raycut::MemorySpace::host : raycut::MemorySpace::device;
  try {
    if (wide.defined())
      work.engine.build(
          raycut::Float64Positions{wide.data_ptr<double>(), static_cast<std::size_t>(wide.size(0))},
          static_cast<float>(cutoff), systems);
    else
      work.engine.build({x.data_ptr<float>(), static_cast<std::size_t>(x.size(0)), space},
                        static_cast<float>(cutoff), systems);
    if (max_pairs && pad_i == pad_j) {
      // Static capacity: the list pass writes the output tensors and the count itself, with no
      // list in between and nothing read back.
      check_max_pairs(*max_pairs);
      const auto on = at::TensorOptions().device(device);
      at::Tensor i = at::empty({*max_pairs}, on.dtype(at::kLong));
      at::Tensor j = at::empty({*max_pairs}, on.dtype(at::kLong));
      at::Tensor shifts = at::empty({*max_pairs, 3}, on.dtype(at::kInt));
      at::Tensor count = at::empty({}, on.dtype(at::kLong));
      work.engine.neighbours(
          raycut::StaticPairs{i.data_ptr<std::int64_t>(), j.data_ptr<std::int64_t>(),
                              shifts.data_ptr<std::int32_t>(), count.data_ptr<std::int64_t>(),
                              static_cast<std::size_t>(*max_pairs), pad_i},
          raycut::ListOptions{.half = half});
      return {i, j, shifts, count};
    }
    raycut::ListOptions options;
    options.half = half;
    options.shifts = true;
    options.coo = true;
    list = device.is_cpu() ? raycut_py::idle_lists().take() : work.device_list();
    work.engine.neighbours(*list, options);
  } catch (const raycut::Error& e) {
    rethrow(e);
  }
  if (device.is_cpu() && !max_pairs) return wrapped_pairs(list);
  return pair_tensors(*list, max_pairs, pad_i, pad_j, device);
}

#ifdef RAYCUT_TORCH_CUDA
// raycut's temporaries from PyTorch's caching allocator, on the stream they are used on: freed
// blocks are reused by later work on that stream only, and a CUDA graph capture takes them from
// its private pool.
class CachingAllocatorMemory final : public raycut::MemoryResource {
 public:
  void* allocate(std::size_t bytes, void* cuda_stream) override {
    return c10::cuda::CUDACachingAllocator::raw_alloc_with_stream(
        bytes, static_cast<cudaStream_t>(cuda_stream));
  }
  void deallocate(void* p, std::size_t, void*) noexcept override {
    c10::cuda::CUDACachingAllocator::raw_delete(p);
  }
};

// Whether the engine's grid can be captured into a CUDA graph for this call: a static list with
// plans reused (Work::reuse_plans), one device cell whose watched boxes still hold (so the cell is
// not copied), no batch index (reading one waits), and an engine that would reuse the plan it
// recorded at an earlier call of as many particles (Engine::reuses_plan_for: a build that plans
// waits).
bool engine_captures(const at::Tensor& positions, double cutoff,
                     const std::optional<at::Tensor>& cell, const std::optional<at::Tensor>& pbc,
                     const std::optional<at::Tensor>& batch, bool static_list) {
  if (!static_list || !Work::reuse_plans() || !cell || !cell->is_cuda() || cell->dim() != 2 ||
      batch)
    return false;
  const c10::cuda::CUDAGuard guard(positions.device());
  Work& work = work_for(positions.device());
  const auto stream = c10::cuda::getCurrentCUDAStream(positions.device().index()).stream();
  if (!work.cell_watch.holds(*cell, pbc, stream) || work.cell_watch.boxes.size() != 1) return false;
  const auto n = static_cast<std::size_t>(positions.size(0));
  return work.engine.reuses_plan_for({nullptr, n, raycut::MemorySpace::device},
                                     static_cast<float>(cutoff),
                                     raycut::Systems::periodic(work.cell_watch.boxes[0]));
}

// Whether a neighbor_list call takes the stream-ordered small-system pass: CUDA tensors, systems
// small enough by raycut's policy, or any size while the current stream is being captured into a
// CUDA graph (torch.cuda.graph, torch.compile's "reduce-overhead") unless the engine's grid can
// be captured (engine_captures): an engine that plans waits on the host, the pass does not (with
// cells from 2,048 particles a system). The number of systems is what the host knows: B of a
// (B, 3, 3) cell, else 1 (the batch's is data-dependent and is never read back). pbc without a
// cell stays on the engine, which checks that no axis is periodic.
bool takes_small_systems_pass(const at::Tensor& positions, double cutoff,
                              const std::optional<at::Tensor>& cell,
                              const std::optional<at::Tensor>& pbc,
                              const std::optional<at::Tensor>& batch, bool static_list) {
  if (!positions.is_cuda() || (pbc && !cell)) return false;
  if (c10::cuda::currentStreamCaptureStatusMayInitCtx() != c10::cuda::CaptureStatus::None)
    return !engine_captures(positions, cutoff, cell, pbc, batch, static_list);
  const std::int64_t systems = cell && cell->dim() == 3 ? cell->size(0) : 1;
  return raycut::prefer_small_systems(static_cast<std::size_t>(positions.size(0)),
                                      static_cast<std::size_t>(systems));
}

// `t` on `device` as `dtype`, C-contiguous: `t` itself where it is so already, without the
// dispatcher calls that a no-op to() and contiguous() still cost (at a hundred particles the
// call is mostly such per-operation costs).
at::Tensor on_device_as(const at::Tensor& t, const at::Device& device, at::ScalarType dtype) {
  if (t.device() == device && t.scalar_type() == dtype && t.is_contiguous()) return t;
  return t.to(device, dtype).contiguous();
}

// The small-system pass on the positions' device and current stream, into tensors that torch
// allocates: nothing here reads device data or waits, so bad values (NaN, an unsorted batch,
// a singular cell, a system without its cell) show as a negative count
// (raycut/device_pairs.hpp's codes), and a list past max_pairs as a count above it. Positions as
// given (float32 or float64, decided in double); cell in their dtype; pbc bool and batch int64 on
// the device (tensors elsewhere are copied there, which waits).
Pairs small_systems_pairs(const at::Tensor& positions, double cutoff,
                          const std::optional<at::Tensor>& cell,
                          const std::optional<at::Tensor>& pbc,
                          const std::optional<at::Tensor>& batch, bool half,
                          std::int64_t max_pairs) {
  check_max_pairs(max_pairs);
  const at::Device device = positions.device();
  const c10::cuda::CUDAGuard guard(device);
  const at::Tensor x = on_device_as(positions, device, positions.scalar_type());
  const std::int64_t n = x.size(0);
  const auto on_device = at::TensorOptions().device(device);

  raycut::DeviceSystems systems;
  systems.positions = x.data_ptr();
  systems.scalar =
      x.scalar_type() == at::kDouble ? raycut::Scalar::float64 : raycut::Scalar::float32;
  systems.size = static_cast<std::size_t>(n);
  at::Tensor cells, flags, index;  // kept alive until the pass is queued
  std::int64_t cell_count = 1, flag_count = 1;
  if (cell) {
    check_cell(*cell);
    // (3, 3) or (B, 3, 3) as given: the pass reads them flat.
    cells = on_device_as(*cell, device, x.scalar_type());
    cell_count = cells.dim() == 3 ? cells.size(0) : 1;
    systems.cells = cells.data_ptr();
    systems.cell_count = static_cast<std::size_t>(cell_count);
  }
  if (pbc) {
    check_pbc(*pbc);
    flags = on_device_as(*pbc, device, at::kBool);  // (3,) or (B, 3), likewise
    flag_count = flags.dim() == 2 ? flags.size(0) : 1;
    systems.pbc = flags.data_ptr<bool>();
    systems.pbc_count = static_cast<std::size_t>(flag_count);
  }
  check_system_counts(cell_count, flag_count);
  check_systems_are_told(std::max(cell_count, flag_count), batch.has_value(), "batch");
  if (batch) {
    check_batch(*batch, n, "batch");
    index = on_device_as(*batch, device, at::kLong);
    systems.batch = index.data_ptr<std::int64_t>();
  }

  at::Tensor i = at::empty({max_pairs}, on_device.dtype(at::kLong));
  at::Tensor j = at::empty({max_pairs}, on_device.dtype(at::kLong));
  at::Tensor shifts = at::empty({max_pairs, 3}, on_device.dtype(at::kInt));
  at::Tensor count = at::empty({}, on_device.dtype(at::kLong));
  raycut::StaticPairs out;
  out.i = i.data_ptr<std::int64_t>();
  out.j = j.data_ptr<std::int64_t>();
  out.shifts = shifts.data_ptr<std::int32_t>();
  out.count = count.data_ptr<std::int64_t>();
  out.capacity = static_cast<std::size_t>(max_pairs);
  out.pad_index = n;
  raycut::PairOptions options;
  options.half = half;
  CachingAllocatorMemory memory;
  const raycut::Context ctx{c10::cuda::getCurrentCUDAStream(device.index()).stream(), &memory};
  try {
    raycut::list_pairs_small_systems(ctx, systems, cutoff, options, out);
  } catch (const raycut::Error& e) {
    rethrow(e);
  }
  return {i, j, shifts, count};
}

// The first particle with a NaN or infinite coordinate, named as the engine names it: bad data
// shows as a count code on the device, and its row is looked up only here, on the error's path.
// NaN comes first: the pass keeps the most negative code, which may be another error's.
void name_non_finite(const at::Tensor& positions) {
  const at::Tensor rows = at::isfinite(positions).all(1).logical_not().nonzero();
  if (rows.size(0) == 0) return;
  const std::int64_t i = rows[0][0].item<std::int64_t>();
  const at::Tensor p = positions[i].to(at::kDouble).cpu();
  TORCH_CHECK_VALUE(false, "non-finite coordinate (NaN or infinite) at positions index ", i, ": (",
                    p[0].item<double>(), ", ", p[1].item<double>(), ", ", p[2].item<double>(), ")");
}

// Exact sizing on the small-system pass: one pass into a capacity guessed from this thread's
// last list on the device, one read-back of the count (which also raises for bad input), and a
// second pass only when the guess was short. The outputs are the first `count` entries.
Pairs exact_small_systems_pairs(const at::Tensor& positions, double cutoff,
                                const std::optional<at::Tensor>& cell,
                                const std::optional<at::Tensor>& pbc,
                                const std::optional<at::Tensor>& batch, bool half) {
  thread_local std::map<int, std::int64_t> last_count;
  std::int64_t& guess = last_count[positions.device().index()];
  const std::int64_t capacity = std::max<std::int64_t>(1024, guess + guess / 4);
  Pairs pairs = small_systems_pairs(positions, cutoff, cell, pbc, batch, half, capacity);
  const raycut::Context ctx{c10::cuda::getCurrentCUDAStream(positions.device().index()).stream()};
  std::int64_t count = 0;
  try {
    count = raycut::read_pair_count(ctx, std::get<3>(pairs).data_ptr<std::int64_t>());
  } catch (const raycut::Error& e) {
    if (e.code() == raycut::ErrorCode::invalid_input) name_non_finite(positions);
    rethrow(e);
  }
  guess = count;
  if (count > capacity)
    pairs = small_systems_pairs(positions, cutoff, cell, pbc, batch, half, count);
  auto& [i, j, shifts, found] = pairs;
  return {i.narrow(0, 0, count), j.narrow(0, 0, count), shifts.narrow(0, 0, count), found};
}
#endif

// The boxes of a call's cell and pbc. Where plans are reused, a static list with a device cell
// takes those of the thread's last copy of that cell and pbc while no comparison has found either
// changed, and after() queues the comparisons behind the list (Work::CellWatch); every other call
// copies the cell (boxes_of: one wait for a device cell, one more for a device pbc).
class CallBoxes {
 public:
  CallBoxes(const at::Tensor& points, const std::optional<at::Tensor>& cell,
            const std::optional<at::Tensor>& pbc, bool static_list) {
#ifdef RAYCUT_TORCH_CUDA
    if (Work::reuse_plans() && static_list && cell && cell->is_cuda()) {
      const c10::cuda::CUDAGuard guard(points.device());  // a new Work is made on its device
      watch_ = &work_for(points.device()).cell_watch;
      cell_ = *cell;
      if (pbc) pbc_ = *pbc;
      boxes = watched(*watch_, *cell, pbc);
      return;
    }
#endif
    boxes = boxes_of(cell, pbc);
  }
  std::vector<raycut::Box> boxes;

  // After the list of `out` is queued: the comparison that makes its count
  // count_plan_outgrown where the cell is not the one the boxes came from.
  void after(const Pairs& out) const {
#ifdef RAYCUT_TORCH_CUDA
    if (!watch_) return;
    const c10::cuda::CUDAGuard guard(cell_.device());
    const auto stream = c10::cuda::getCurrentCUDAStream(cell_.device().index()).stream();
    std::int64_t* count = std::get<3>(out).data_ptr<std::int64_t>();
    if (pbc_.defined() && pbc_.is_cuda()) {
      const at::Tensor pbc_now = pbc_.contiguous();
      watch_->changed.compare(pbc_now.data_ptr(), watch_->seen_pbc.data_ptr(),
                              watch_->seen_pbc.nbytes(), count, raycut::count_plan_outgrown,
                              stream);
    }
    const at::Tensor now = cell_.contiguous();
    watch_->changed.compare(now.data_ptr(), watch_->seen.data_ptr(), watch_->seen.nbytes(), count,
                            raycut::count_plan_outgrown, stream);
#else
    (void)out;
#endif
  }

 private:
#ifdef RAYCUT_TORCH_CUDA
  static std::vector<raycut::Box> watched(Work::CellWatch& watch, const at::Tensor& cell,
                                          const std::optional<at::Tensor>& pbc) {
    if (watch.holds(cell, pbc, c10::cuda::getCurrentCUDAStream(cell.device().index()).stream()))
      return watch.boxes;
    watch.boxes = boxes_of(cell, pbc);
    watch.seen = cell.contiguous().clone();
    watch.pbc_values = pbc ? pbc->to(at::kCPU).contiguous().clone() : at::Tensor();
    watch.seen_pbc = pbc ? watch.pbc_values.to(cell.device()) : at::Tensor();
    return watch.boxes;
  }
  Work::CellWatch* watch_ = nullptr;
  at::Tensor cell_, pbc_;
#endif
};

Pairs neighbor_list(const at::Tensor& positions, double cutoff,
                    const std::optional<at::Tensor>& cell, const std::optional<at::Tensor>& pbc,
                    const std::optional<at::Tensor>& batch, bool half,
                    std::optional<std::int64_t> max_pairs) {
#ifdef RAYCUT_TORCH_CUDA
  check_points(positions, "positions");
  if (takes_small_systems_pass(positions, cutoff, cell, pbc, batch, max_pairs.has_value())) {
    if (max_pairs)
      return small_systems_pairs(positions, cutoff, cell, pbc, batch, half, *max_pairs);
    return exact_small_systems_pairs(positions, cutoff, cell, pbc, batch, half);
  }
#endif
  const at::Tensor x = search_points(positions, "positions");
  const std::int64_t n = x.size(0);
  const CallBoxes boxes(positions, cell, pbc, max_pairs.has_value());
  const raycut::Systems systems =
      systems_of(boxes.boxes, system_index(batch, n, "batch"), n, at::Tensor(), 0,
                 /*with_queries=*/false, "batch");
  const bool wide = positions.is_cpu() && positions.scalar_type() == at::kDouble;
  Pairs out =
      run(x, cutoff, systems, half, max_pairs, n, n, wide ? positions.contiguous() : at::Tensor());
  boxes.after(out);
  return out;
}

Pairs radius(const at::Tensor& points, const at::Tensor& queries, double cutoff,
             const std::optional<at::Tensor>& cell, const std::optional<at::Tensor>& pbc,
             const std::optional<at::Tensor>& batch_points,
             const std::optional<at::Tensor>& batch_queries,
             std::optional<std::int64_t> max_pairs) {
  const at::Tensor x = search_points(points, "points");
  const at::Tensor q = search_points(queries, "queries");
  TORCH_CHECK_VALUE(q.device() == x.device(), "queries must be on the device of points (",
                    x.device(), "), got ", q.device());
  const std::int64_t n = x.size(0), m = q.size(0);
  raycut::Systems systems = systems_of(
      boxes_of(cell, pbc), system_index(batch_points, n, "batch_points"), n,
      system_index(batch_queries, m, "batch_queries"), m, /*with_queries=*/true, "batch_points");
  const auto space = x.is_cpu() ? raycut::MemorySpace::host : raycut::MemorySpace::device;
  systems.queries = {q.data_ptr<float>(), static_cast<std::size_t>(m), space};
  // No query points is still a query build (the targets are the M = 0 queries, not the points).
  if (m == 0) systems.queries.xyz = x.data_ptr<float>();
  // Padding: i = M (no query), j = N (no point).
  return run(x, cutoff, systems, /*half=*/false, max_pairs, m, n);
}

// A copy of `count` values at `data` (where the engine keeps its results: host or `device`) as a
// new float32 tensor of `shape` on `device` (on the current stream for CUDA).
at::Tensor copied(const float* data, at::IntArrayRef shape, const at::Device& device) {
  return at::from_blob(const_cast<float*>(data), shape, at::TensorOptions().device(device)).clone();
}

// The fused Lennard-Jones pass (Kernel::lj_forces, as Engine.compute("lj_forces")): per-particle
// energy (N,), force (N, 3) and virial (N, 6) float32, in one pass over the pairs, no list.
std::tuple<at::Tensor, at::Tensor, at::Tensor> lj_forces(const at::Tensor& positions, double cutoff,
                                                         double epsilon, double sigma,
                                                         const std::optional<at::Tensor>& cell,
                                                         const std::optional<at::Tensor>& pbc,
                                                         const std::optional<at::Tensor>& batch) {
  const at::Tensor x = search_points(positions, "positions");
  const std::int64_t n = x.size(0);
  const raycut::Systems systems =
      systems_of(boxes_of(cell, pbc), system_index(batch, n, "batch"), n, at::Tensor(), 0,
                 /*with_queries=*/false, "batch");
  const at::Device device = x.device();
  const OnDevice on(device);
  Work& work = on.work;
  const auto space = device.is_cpu() ? raycut::MemorySpace::host : raycut::MemorySpace::device;
  raycut::KernelOptions options;
  options.lj_epsilon = static_cast<float>(epsilon);
  options.lj_sigma = static_cast<float>(sigma);
  try {
    work.engine.build({x.data_ptr<float>(), static_cast<std::size_t>(n), space},
                      static_cast<float>(cutoff), systems);
    work.engine.run(raycut::Kernel::lj_forces, options);
  } catch (const raycut::Error& e) {
    rethrow(e);
  }
  if (n == 0)
    return {at::empty({0}, x.options()), at::empty({0, 3}, x.options()),
            at::empty({0, 6}, x.options())};
  const raycut::ResultsView results = work.engine.results_view();
  return {copied(results.energy, {n}, device), copied(results.force, {n, 3}, device),
          copied(results.virial, {n, 6}, device)};
}

}  // namespace

TORCH_LIBRARY(raycut, m) {
  m.def(
      "neighbor_list(Tensor positions, float cutoff, Tensor? cell=None, Tensor? pbc=None, "
      "Tensor? batch=None, bool half=False, int? max_pairs=None) -> (Tensor i, Tensor j, "
      "Tensor S, Tensor count)");
  m.def(
      "radius(Tensor points, Tensor queries, float cutoff, Tensor? cell=None, Tensor? pbc=None, "
      "Tensor? batch_points=None, Tensor? batch_queries=None, int? max_pairs=None) -> (Tensor i, "
      "Tensor j, Tensor S, Tensor count)");
  m.def(
      "lj_forces(Tensor positions, float cutoff, float epsilon=1.0, float sigma=1.0, "
      "Tensor? cell=None, Tensor? pbc=None, Tensor? batch=None) -> (Tensor energy, Tensor force, "
      "Tensor virial)");
}

TORCH_LIBRARY_IMPL(raycut, CPU, m) {
  m.impl("neighbor_list", &neighbor_list);
  m.impl("radius", &radius);
  m.impl("lj_forces", &lj_forces);
}

#ifdef RAYCUT_TORCH_CUDA
// The same kernels on CUDA tensors: the grid on the tensors' device and current stream (the
// boxes and batch offsets are read on the host), or for neighbor_list with max_pairs on small
// systems the stream-ordered pass that reads nothing back (takes_small_systems_pass).
TORCH_LIBRARY_IMPL(raycut, CUDA, m) {
  m.impl("neighbor_list", &neighbor_list);
  m.impl("radius", &radius);
  m.impl("lj_forces", &lj_forces);
}
#endif
