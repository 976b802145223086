// Call latency of a neighbour list for small systems and batches (docs/benchmarks.md, "Latency of
// small systems"): the stream-ordered static-capacity pair list (raycut/device_pairs.hpp), eager
// and replayed from a CUDA graph, against raycut::Engine's build + neighbours (exact sizes, host
// synchronisations), on one workload:
//
//   lj-pbc  a periodic Lennard-Jones liquid: density 0.8442, cutoff 2.5, positions uniform random
//           in a cube of side (n / 0.8442)^(1/3) per system, float32. Single systems of
//           --sizes particles and batches (--batches SxN: S systems of N particles, each its own
//           cube: one cell per system, a sorted int64 system index per particle).
//
// Rows (interface cpp): mode eager / capacity static (list_pairs_small_systems on a non-default
// stream into a StaticPairBuffer of 1.25 x the true count, found once with
// list_pairs_small_systems_growing), mode graph / capacity static (the same call captured once
// in global mode, replayed with cudaGraphLaunch), mode eager / capacity exact (Engine("grid")
// build + neighbours with shifts, engine and buffer reused), mode eager / capacity engine-static
// (the same build, then Engine::neighbours into a StaticPairs of 1.25 x the count: no read-back
// of the total), mode eager (and graph, when its capture succeeds) / capacity engine-reused (the
// same with an untimed engine that reuses its plan, Engine::set_reuse_plan: nothing read back
// after its first build). The small path is measured where
// prefer_small_systems says so, everywhere with --all; --crossover adds single systems of 2000,
// 4000 and 8000 particles on every path.
//
// Timing: after warm-up, --reps repetitions of a loop of K calls (K doubled until a loop takes
// --min-loop-ms), the stream synchronised only around each loop, host wall clock; us_per_call is
// the median over repetitions of loop time / K. `kernels`: kernel nodes of the captured graph;
// `syncs`: 0 when the global-mode capture succeeded (capture fails on any synchronisation);
// both empty for the engine rows.
//
// Exit codes: 0 measured and checked, 1 a failure or a check that did not hold, 2 bad arguments,
// 77 no CUDA device (nothing to measure).
#include <cuda_runtime.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <fstream>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "raycut/box.hpp"
#include "raycut/context.hpp"
#include "raycut/device_pairs.hpp"
#include "raycut/engine.hpp"
#include "raycut/tools/generators.hpp"
#include "raycut/tools/system_info.hpp"

namespace {

constexpr double kDensity = 0.8442;
constexpr double kCutoff = 2.5;
constexpr const char* kUsage = R"(raycut_latency_bench: call latency of small-system neighbour lists

usage: raycut_latency_bench [options]
  --output FILE        CSV rows (columns: workload,systems,n_per_system,interface,mode,
                       capacity,us_per_call,kernels,syncs,gpu,driver,cuda)
  --sizes LIST         single systems, particles each (default 128,1000,10000,100000)
  --batches LIST       batches as SxN, S systems of N particles (default 32x100,256x100,512x128;
                       "none": no batches)
  --all                the small path on every workload (default: where
                       raycut::prefer_small_systems says so)
  --crossover          also single systems of 2000, 4000 and 8000 particles, every path
  --search S           the small path's sources: automatic (default), all-pairs or cells
                       (the rows' interface is then cpp-all-pairs or cpp-cells, and the
                       engine's rows are left out)
  --reps R             timed repetitions of each loop (default 30, at least 1)
  --min-loop-ms T      a timed loop lasts at least this long (default 2)
  --seed S             positions' random seed (default 1)
  --help               this text
Exit codes: 0 done, 1 failure or a failed check, 2 bad arguments, 77 no CUDA device.
)";

void check_cuda(cudaError_t e, const char* what) {
  if (e != cudaSuccess) throw std::runtime_error(std::string(what) + ": " + cudaGetErrorString(e));
}

struct BadArgument : std::invalid_argument {
  using std::invalid_argument::invalid_argument;
};

struct Options {
  std::string output;
  std::vector<std::size_t> sizes = {128, 1000, 10000, 100000};
  std::vector<std::pair<std::size_t, std::size_t>> batches = {{32, 100}, {256, 100}, {512, 128}};
  bool all = false;
  bool crossover = false;
  raycut::SourceSearch search = raycut::SourceSearch::automatic;
  std::string search_name;  // as given; empty for automatic
  int reps = 30;
  double min_loop_ms = 2.0;
  std::uint64_t seed = 1;
};

std::size_t parse_count(const std::string& text, const std::string& option) {
  char* end = nullptr;
  errno = 0;
  const unsigned long long v = std::strtoull(text.c_str(), &end, 10);
  if (text.empty() || text[0] == '-' || *end != '\0' || errno != 0 || v == 0)
    throw BadArgument(option + ": '" + text + "' is not a whole number >= 1");
  return static_cast<std::size_t>(v);
}

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::size_t start = 0;
  while (true) {
    const std::size_t at = text.find(separator, start);
    parts.push_back(text.substr(start, at - start));
    if (at == std::string::npos) return parts;
    start = at + 1;
  }
}

Options parse(int argc, char** argv, bool& help) {
  Options o;
  help = false;
  for (int a = 1; a < argc; ++a) {
    const std::string arg = argv[a];
    auto value = [&]() -> std::string {
      if (a + 1 >= argc) throw BadArgument(arg + " needs a value");
      return argv[++a];
    };
    if (arg == "--help" || arg == "-h") {
      help = true;
    } else if (arg == "--output") {
      o.output = value();
    } else if (arg == "--sizes") {
      o.sizes.clear();
      for (const std::string& s : split(value(), ',')) o.sizes.push_back(parse_count(s, arg));
    } else if (arg == "--batches") {
      o.batches.clear();
      const std::string list = value();
      if (list == "none") continue;
      for (const std::string& b : split(list, ',')) {
        const std::vector<std::string> sn = split(b, 'x');
        if (sn.size() != 2)
          throw BadArgument(arg + ": '" + b + "' is not SxN (systems x particles, e.g. 32x100)");
        o.batches.emplace_back(parse_count(sn[0], arg), parse_count(sn[1], arg));
      }
    } else if (arg == "--all") {
      o.all = true;
    } else if (arg == "--crossover") {
      o.crossover = true;
    } else if (arg == "--search") {
      o.search_name = value();
      if (o.search_name == "all-pairs")
        o.search = raycut::SourceSearch::all_pairs;
      else if (o.search_name == "cells")
        o.search = raycut::SourceSearch::cells;
      else if (o.search_name == "automatic")
        o.search_name.clear();
      else
        throw BadArgument(arg + ": '" + o.search_name + "' is not automatic, all-pairs or cells");
    } else if (arg == "--reps") {
      o.reps = static_cast<int>(std::min<std::size_t>(parse_count(value(), arg), 1 << 20));
    } else if (arg == "--min-loop-ms") {
      const std::string text = value();
      char* end = nullptr;
      o.min_loop_ms = std::strtod(text.c_str(), &end);
      if (text.empty() || *end != '\0' || !std::isfinite(o.min_loop_ms) || o.min_loop_ms <= 0)
        throw BadArgument(arg + ": '" + text + "' is not a positive number of milliseconds");
    } else if (arg == "--seed") {
      o.seed = parse_count(value(), arg);
    } else {
      throw BadArgument("unknown option '" + arg + "' (--help lists them)");
    }
  }
  return o;
}

// One workload: `systems` periodic cubes of `per_system` particles each.
struct Workload {
  std::size_t systems = 1, per_system = 0;
  bool forced_small = false;  // --crossover sizes: the small path whatever the policy says
  std::size_t particles() const { return systems * per_system; }
};

// A device allocation freed at scope end.
class DeviceBuffer {
 public:
  template <class T>
  explicit DeviceBuffer(const std::vector<T>& host) : bytes_(host.size() * sizeof(T)) {
    check_cuda(cudaMalloc(&data_, std::max<std::size_t>(bytes_, 1)), "cudaMalloc");
    if (bytes_)
      check_cuda(cudaMemcpy(data_, host.data(), bytes_, cudaMemcpyHostToDevice), "cudaMemcpy");
  }
  ~DeviceBuffer() { cudaFree(data_); }
  DeviceBuffer(const DeviceBuffer&) = delete;
  DeviceBuffer& operator=(const DeviceBuffer&) = delete;
  void* data() const { return data_; }

 private:
  void* data_ = nullptr;
  std::size_t bytes_ = 0;
};

// The workload's arrays on the device, in both forms the two interfaces take.
struct DeviceWorkload {
  std::size_t n = 0;
  double side = 0;
  std::vector<float> cells;  // (systems, 3, 3)
  std::vector<std::uint8_t> pbc;
  std::vector<std::int64_t> batch;
  std::optional<DeviceBuffer> xyz, d_cells, d_pbc, d_batch;
  raycut::DeviceSystems small;
  raycut::Systems engine_systems;

  DeviceWorkload(const Workload& w, std::uint64_t seed) : n(w.particles()) {
    side = std::cbrt(static_cast<double>(w.per_system) / kDensity);
    // The suite's generator (uniform in [0, 1)^3, independent per particle) scaled to the cube:
    // each system's run of particles is its own uniform sample.
    raycut::PointCloud cloud = raycut::uniform_suite(1, static_cast<int>(n), seed);
    for (float& x : cloud.xyz) x = static_cast<float>(x * side);
    const raycut::Box box = raycut::Box::orthorhombic(side, side, side);
    for (std::size_t s = 0; s < w.systems; ++s) {
      for (int r = 0; r < 3; ++r) {
        pbc.push_back(1);
        for (int c = 0; c < 3; ++c) cells.push_back(static_cast<float>(box.cell[r][c]));
      }
      if (w.systems > 1) {
        batch.insert(batch.end(), w.per_system, static_cast<std::int64_t>(s));
        engine_systems.boxes.push_back(box);
        engine_systems.offsets.push_back(s * w.per_system);
      }
    }
    if (w.systems > 1)
      engine_systems.offsets.push_back(n);
    else
      engine_systems.box = box;
    xyz.emplace(cloud.xyz);
    d_cells.emplace(cells);
    d_pbc.emplace(pbc);
    small.positions = xyz->data();
    small.scalar = raycut::Scalar::float32;
    small.size = n;
    small.cells = d_cells->data();
    small.cell_count = w.systems;
    small.pbc = static_cast<const bool*>(d_pbc->data());
    small.pbc_count = w.systems;
    if (w.systems > 1) {
      d_batch.emplace(batch);
      small.batch = static_cast<const std::int64_t*>(d_batch->data());
    }
  }
  raycut::PositionsView positions() const {
    return {static_cast<const float*>(xyz->data()), n, raycut::MemorySpace::device};
  }
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

// The timing rule: K calls per loop, K doubled until one loop lasts min_loop_ms (the doubling
// loops are the warm-up), then `reps` loops; the median of loop time / K in microseconds.
// `sync` waits for the stream: only around a loop.
template <class Call, class Sync>
double us_per_call(Call&& call, Sync&& sync, int reps, double min_loop_ms) {
  using clock = std::chrono::steady_clock;
  auto loop = [&](std::size_t k) {
    sync();
    const auto t0 = clock::now();
    for (std::size_t c = 0; c < k; ++c) call();
    sync();
    return std::chrono::duration<double, std::micro>(clock::now() - t0).count();
  };
  loop(1);  // first call: lazy initialisation, allocations of the memory pool
  std::size_t k = 1;
  while (loop(k) < 1e3 * min_loop_ms && k < (std::size_t{1} << 24)) k *= 2;
  std::vector<double> per_call;
  for (int r = 0; r < reps; ++r) per_call.push_back(loop(k) / static_cast<double>(k));
  return median(per_call);
}

// The host's share of an eager call: `calls` calls queued back to back, timed before the stream
// is waited for (the GPU works behind them), the median over `reps` such loops. Printed beside
// the engine's rows: a row near this is host-bound.
template <class Call, class Sync>
double host_enqueue_us(Call&& call, Sync&& sync, int reps, int calls = 16) {
  using clock = std::chrono::steady_clock;
  std::vector<double> per_call;
  for (int r = 0; r < reps; ++r) {
    sync();
    const auto t0 = clock::now();
    for (int c = 0; c < calls; ++c) call();
    per_call.push_back(std::chrono::duration<double, std::micro>(clock::now() - t0).count() /
                       calls);
  }
  sync();
  return median(per_call);
}

struct Row {
  std::string workload = "lj-pbc";
  std::size_t systems = 0, n_per_system = 0;
  std::string interface = "cpp", mode, capacity;
  double us = 0;
  std::string kernels, syncs;  // empty where not counted
};

std::string csv_field(const std::string& s) {
  if (s.find_first_of(",\"\n") == std::string::npos) return s;
  std::string quoted = "\"";
  for (char c : s) quoted += c == '"' ? std::string("\"\"") : std::string(1, c);
  return quoted + "\"";
}

// The captured graph's kernel nodes (memset, memcpy and memory nodes not counted).
std::size_t kernel_nodes(cudaGraph_t graph) {
  std::size_t count = 0;
  check_cuda(cudaGraphGetNodes(graph, nullptr, &count), "cudaGraphGetNodes");
  std::vector<cudaGraphNode_t> nodes(count);
  if (count) check_cuda(cudaGraphGetNodes(graph, nodes.data(), &count), "cudaGraphGetNodes");
  std::size_t kernels = 0;
  for (cudaGraphNode_t node : nodes) {
    cudaGraphNodeType type;
    check_cuda(cudaGraphNodeGetType(node, &type), "cudaGraphNodeGetType");
    if (type == cudaGraphNodeTypeKernel) ++kernels;
  }
  return kernels;
}

// call() captured in a CUDA graph in global mode (any synchronisation fails it) and
// instantiated; `error` says why not (then `exec` is null).
struct Capture {
  cudaGraph_t graph = nullptr;
  cudaGraphExec_t exec = nullptr;
  std::string error;
  template <class Call>
  Capture(cudaStream_t stream, Call&& call) {
    check_cuda(cudaStreamBeginCapture(stream, cudaStreamCaptureModeGlobal),
               "cudaStreamBeginCapture");
    try {
      call();
    } catch (const std::exception& e) {
      error = e.what();
    }
    const cudaError_t ended = cudaStreamEndCapture(stream, &graph);
    if (error.empty() && ended != cudaSuccess) error = cudaGetErrorString(ended);
    if (error.empty() && cudaGraphInstantiate(&exec, graph, 0) != cudaSuccess)
      error = "cudaGraphInstantiate failed";
    (void)cudaGetLastError();  // a failed capture leaves its error behind
  }
  ~Capture() {
    if (exec) cudaGraphExecDestroy(exec);
    if (graph) cudaGraphDestroy(graph);
  }
  Capture(const Capture&) = delete;
  Capture& operator=(const Capture&) = delete;
};

// What measuring one workload found wrong (empty: every check held).
struct Checks {
  std::vector<std::string> problems;
  void expect(bool ok, const std::string& what) {
    if (!ok) problems.push_back(what);
  }
};

// The small path's rows: eager and graph replays into a static buffer of 1.25 x the true count.
// Returns the true count.
std::int64_t measure_small(const Workload& w, DeviceWorkload& d, cudaStream_t stream,
                           const Options& o, std::vector<Row>& rows, Checks& checks) {
  const raycut::Context ctx{stream, nullptr};
  const auto pad = static_cast<std::int64_t>(d.n);
  raycut::StaticPairBuffer sizing(1024, ctx);
  raycut::PairOptions options;
  options.search = o.search;
  const std::int64_t count =
      raycut::list_pairs_small_systems_growing(ctx, d.small, kCutoff, options, sizing);
  sizing = {};
  const auto capacity = static_cast<std::size_t>(std::ceil(1.25 * static_cast<double>(count)));
  raycut::StaticPairBuffer pairs(std::max<std::size_t>(capacity, 1), ctx);
  const raycut::StaticPairs out = pairs.view(pad);
  auto call = [&] { raycut::list_pairs_small_systems(ctx, d.small, kCutoff, options, out); };
  auto sync = [&] { check_cuda(cudaStreamSynchronize(stream), "cudaStreamSynchronize"); };

  // The graph first: its kernel count and whether it captured describe the eager call too.
  Capture captured(stream, call);
  const std::string& capture_error = captured.error;
  checks.expect(capture_error.empty(), "global-mode capture failed: " + capture_error);
  const std::string kernels =
      capture_error.empty() ? std::to_string(kernel_nodes(captured.graph)) : std::string();
  const std::string syncs = capture_error.empty() ? "0" : "";

  const std::string interface = o.search_name.empty() ? "cpp" : "cpp-" + o.search_name;
  Row row{"lj-pbc", w.systems, w.per_system, interface, "eager", "static", 0, kernels, syncs};
  row.us = us_per_call(call, sync, o.reps, o.min_loop_ms);
  rows.push_back(row);
  checks.expect(
      raycut::read_pair_count(ctx, pairs.count()) == count,
      "eager: the count read after the loops differs from the true count " + std::to_string(count));
  if (captured.exec) {
    auto replay = [&] { check_cuda(cudaGraphLaunch(captured.exec, stream), "cudaGraphLaunch"); };
    check_cuda(cudaMemsetAsync(pairs.count(), 0xff, sizeof(std::int64_t), stream), "cudaMemset");
    row.mode = "graph";
    row.us = us_per_call(replay, sync, o.reps, o.min_loop_ms);
    rows.push_back(row);
    checks.expect(raycut::read_pair_count(ctx, pairs.count()) == count,
                  "graph: the replayed count differs from the true count " + std::to_string(count));
  }
  pairs = {};
  sync();
  std::printf("  small path: %lld pairs, capacity %zu%s\n", static_cast<long long>(count), capacity,
              capture_error.empty() ? "" : " (no graph: capture failed)");
  return count;
}

// The engine's row: build + neighbours with shifts, engine and list reused from call to call.
// Returns its pair count.
std::uint64_t measure_engine(const Workload& w, DeviceWorkload& d, cudaStream_t stream,
                             const Options& o, std::vector<Row>& rows) {
  raycut::Engine engine("grid");
  engine.set_stream(stream);
  raycut::NeighbourListBuffer list;
  raycut::ListOptions options;
  options.shifts = true;
  const float cutoff = static_cast<float>(kCutoff);
  auto call = [&] {
    engine.build(d.positions(), cutoff, d.engine_systems);
    engine.neighbours(list, options);
  };
  auto sync = [&] { check_cuda(cudaStreamSynchronize(stream), "cudaStreamSynchronize"); };
  Row row{"lj-pbc", w.systems, w.per_system, "cpp", "eager", "exact", 0, "", ""};
  row.us = us_per_call(call, sync, o.reps, o.min_loop_ms);
  rows.push_back(row);
  const std::uint64_t pairs = list.pairs();
  std::printf("  engine: %llu pairs\n", static_cast<unsigned long long>(pairs));

  // The same build, then the list into a static capacity (1.25 x the count): no read-back of
  // the total, no list buffers.
  raycut::Context ctx;
  ctx.stream = stream;
  raycut::StaticPairBuffer buffer(pairs + pairs / 4 + 1, ctx);
  const raycut::StaticPairs out = buffer.view(static_cast<std::int64_t>(w.particles()));
  auto static_call = [&] {
    engine.build(d.positions(), cutoff, d.engine_systems);
    engine.neighbours(out, raycut::ListOptions{});
  };
  Row static_row{"lj-pbc", w.systems, w.per_system, "cpp", "eager", "engine-static", 0, "", ""};
  static_row.us = us_per_call(static_call, sync, o.reps, o.min_loop_ms);
  rows.push_back(static_row);
  const std::int64_t count = raycut::read_pair_count(ctx, buffer.count());
  if (count != static_cast<std::int64_t>(pairs))
    throw std::runtime_error("the engine's static list counts " + std::to_string(count) +
                             " pairs, its exact list " + std::to_string(pairs));

  // An untimed engine that reuses its plan (Engine::set_reuse_plan): after its first build,
  // nothing read back. Also tried in a global-mode capture (reported, not required).
  raycut::Engine reusing("grid");
  reusing.set_stream(stream);
  reusing.set_timed(false);
  reusing.set_reuse_plan(true);
  auto reused_call = [&] {
    reusing.build(d.positions(), cutoff, d.engine_systems);
    reusing.neighbours(out, raycut::ListOptions{});
  };
  reused_call();  // plans and records
  Row reused_row{"lj-pbc", w.systems, w.per_system, "cpp", "eager", "engine-reused", 0, "", ""};
  reused_row.us = us_per_call(reused_call, sync, o.reps, o.min_loop_ms);
  rows.push_back(reused_row);
  const std::int64_t reused_count = raycut::read_pair_count(ctx, buffer.count());
  if (reused_count != static_cast<std::int64_t>(pairs))
    throw std::runtime_error("the reusing engine's static list counts " +
                             std::to_string(reused_count) + " pairs, the exact list " +
                             std::to_string(pairs));
  const Capture captured(stream, reused_call);
  if (captured.exec) {
    auto replay = [&] { check_cuda(cudaGraphLaunch(captured.exec, stream), "cudaGraphLaunch"); };
    reused_row.mode = "graph";
    reused_row.kernels = std::to_string(kernel_nodes(captured.graph));
    reused_row.syncs = "0";
    reused_row.us = us_per_call(replay, sync, o.reps, o.min_loop_ms);
    rows.push_back(reused_row);
    if (raycut::read_pair_count(ctx, buffer.count()) != static_cast<std::int64_t>(pairs))
      throw std::runtime_error("the reusing engine's replayed count differs");
  }
  std::printf("  engine reusing its plan: %lld pairs%s%s\n", static_cast<long long>(reused_count),
              captured.error.empty() ? "" : "; no graph: ", captured.error.c_str());
  std::printf("  host enqueue per call: engine-static %.1f us, engine-reused %.1f us\n",
              host_enqueue_us(static_call, sync, o.reps),
              host_enqueue_us(reused_call, sync, o.reps));
  return pairs;
}

std::vector<Workload> workloads(const Options& o) {
  std::vector<Workload> list;
  for (std::size_t n : o.sizes) list.push_back({1, n, false});
  if (o.crossover)
    for (std::size_t n : {2000, 4000, 8000}) list.push_back({1, n, true});
  for (const auto& [s, n] : o.batches) list.push_back({s, n, false});
  return list;
}

void write_csv(const std::string& path, const std::vector<Row>& rows,
               const raycut::SystemInfo& info) {
  std::ofstream out(path);
  if (!out) throw std::runtime_error("--output: cannot write '" + path + "'");
  out << "workload,systems,n_per_system,interface,mode,capacity,us_per_call,kernels,syncs,gpu,"
         "driver,cuda\n";
  for (const Row& r : rows) {
    char us[32];
    std::snprintf(us, sizeof us, "%.3f", r.us);
    out << r.workload << ',' << r.systems << ',' << r.n_per_system << ',' << r.interface << ','
        << r.mode << ',' << r.capacity << ',' << us << ',' << r.kernels << ',' << r.syncs << ','
        << csv_field(info.gpu) << ',' << csv_field(info.driver) << ',' << csv_field(info.cuda)
        << '\n';
  }
  if (!out) throw std::runtime_error("--output: writing '" + path + "' failed");
}

int run(const Options& o) {
  int devices = 0;
  const cudaError_t probe = cudaGetDeviceCount(&devices);
  if (probe != cudaSuccess || devices == 0) {
    std::fprintf(stderr, "raycut_latency_bench: no CUDA device (%s): nothing to measure\n",
                 probe != cudaSuccess ? cudaGetErrorString(probe) : "0 devices");
    return 77;
  }
  const raycut::SystemInfo info = raycut::system_info();
  std::printf("lj-pbc latency on %s (driver %s, CUDA %s), %d reps, loops >= %g ms\n",
              info.gpu.c_str(), info.driver.c_str(), info.cuda.c_str(), o.reps, o.min_loop_ms);
  cudaStream_t stream = nullptr;
  check_cuda(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking), "cudaStreamCreate");
  std::vector<Row> rows;
  Checks checks;
  for (const Workload& w : workloads(o)) {
    std::printf("lj-pbc %zu x %zu:\n", w.systems, w.per_system);
    std::fflush(stdout);
    // A failing workload is reported and the others still measured (a sticky CUDA error
    // fails the rest too: exit 1 either way).
    try {
      DeviceWorkload d(w, o.seed);
      std::int64_t small_count = -1;
      if (o.all || w.forced_small || raycut::prefer_small_systems(w.particles(), w.systems))
        small_count = measure_small(w, d, stream, o, rows, checks);
      else
        std::printf("  small path skipped (prefer_small_systems is false; --all measures it)\n");
      if (!o.search_name.empty()) continue;  // a forced search: its small-path rows only
      const std::uint64_t engine_count = measure_engine(w, d, stream, o, rows);
      // The engine decides in float32 and the small path in double: a pair exactly at the
      // cutoff could differ in principle, so a difference is reported, not failed.
      if (small_count >= 0 && engine_count != static_cast<std::uint64_t>(small_count))
        std::printf("  note: the engine lists %llu pairs, the small path %lld\n",
                    static_cast<unsigned long long>(engine_count),
                    static_cast<long long>(small_count));
    } catch (const std::exception& e) {
      checks.expect(false, "lj-pbc " + std::to_string(w.systems) + " x " +
                               std::to_string(w.per_system) + ": " + e.what());
    }
    std::fflush(stdout);
  }
  check_cuda(cudaStreamDestroy(stream), "cudaStreamDestroy");

  std::printf("\n%-8s %8s %12s %-6s %-7s %-8s %12s %8s %6s\n", "workload", "systems",
              "n_per_system", "iface", "mode", "capacity", "us_per_call", "kernels", "syncs");
  for (const Row& r : rows)
    std::printf("%-8s %8zu %12zu %-6s %-7s %-8s %12.2f %8s %6s\n", r.workload.c_str(), r.systems,
                r.n_per_system, r.interface.c_str(), r.mode.c_str(), r.capacity.c_str(), r.us,
                r.kernels.empty() ? "-" : r.kernels.c_str(),
                r.syncs.empty() ? "-" : r.syncs.c_str());
  if (!o.output.empty()) {
    write_csv(o.output, rows, info);
    std::printf("wrote %zu rows to %s\n", rows.size(), o.output.c_str());
  }
  for (const std::string& p : checks.problems)
    std::fprintf(stderr, "raycut_latency_bench: check failed: %s\n", p.c_str());
  return checks.problems.empty() ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  bool help = false;
  try {
    o = parse(argc, argv, help);
  } catch (const BadArgument& e) {
    std::fprintf(stderr, "raycut_latency_bench: %s\n", e.what());
    return 2;
  }
  if (help) {
    std::fputs(kUsage, stdout);
    return 0;
  }
  try {
    return run(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "raycut_latency_bench: %s\n", e.what());
    return 1;
  }
}
