// Neighbour lists against fused kernels, timed as docs/benchmarks.md says: CUDA events
// on the engine's stream around the whole operation, from device positions to a complete device
// result; one warm-up, then the median (and min/max) of --reps repetitions; each operation
// "cold" (a fresh Engine and fresh result buffers constructed inside the timing: every
// allocation is timed) and "prepared" (one Engine and its buffers reused from call to call).
//
//   neighbour_bench --methods grid,grid-paper --betas 16,32 --lj-liquid --out lists.csv
//
// Inputs: the paper's uniform suite exactly as `raycut bench -s uniform` makes it
// (raycut::uniform_suite(beta, p, seed 1): N = p beta^3 in [0,1)^3, cutoff 1/beta), and with
// --lj-liquid an LJ liquid: N = 2^20 uniform random in a cube at density 0.8442, rc = 2.5,
// not periodic (the rows measured before the engine had boxes).
//
// With --periodic, the periodic workloads of docs/benchmarks.md (density 0.8442,
// rc 2.5, cube sides from the density, uniform random positions in [0, side)^3 of each system):
//   lj-liquid-pbc  one periodic cube of 2^20 particles (side ~107.5; --periodic-n: other sizes)
//   batch-pbc      512 periodic cubes of 128 particles (side ~5.33) as one batch
//                  (Systems::offsets, one box shared by all), and 64 cubes of 4096 (side ~16.9)
// with their own operations (--ops overrides them), the lists with image shifts:
//   list_full_s     build + neighbours(buffer, {shifts})
//   list_half_s     build + neighbours(buffer, {half, shifts})
//   list_half_any_s build + neighbours(buffer, {half, any_row, shifts}): the half stencil
//   lj_forces_only  run(Kernel::lj_forces) alone, on an engine built before the timing (cold:
//                   a fresh one, so the result arrays are allocated inside the timing)
// (lj-liquid-pbc: build, count, list_full_s, list_half_s, lj_forces, lj_forces_only,
// list_half_any_s; the
// batches: build, count, list_full_s). Their rows have param = systems, p = particles per
// system.
//
// Operations (each but build and list_only_full includes Engine::build):
//   build           Engine::build on device positions
//   count           build + run(Kernel::count)
//   list_full       build + neighbours(buffer): full CSR
//   list_half       build + neighbours(buffer, {half})
//   list_full_dv    build + neighbours(buffer, {distances, vectors})
//   padded          build + padded_neighbours(buffer, {.k = K}), K = ceil(1.25 x mean count)
//   lj, lj_forces   build + run(Kernel::lj / Kernel::lj_forces)
//   functor_lj      build + raycut::cuda::for_each_pair with a user functor carrying the
//                   built-in LJ energy math and its own output buffer
//   list_only_full  neighbours(buffer) alone, on an engine built before the timing
//   list_full_s, list_half_s, list_half_any_s, lj_forces_only: above (any input; shifts are 0
//                   without a box)
// One CSV row per (input, method, operation, mode); `pairs` is the ordered in-range pair count
// (sum of Kernel::count), `entries` what the result holds, `check` whether it agrees (list
// entries vs pairs; functor energies bitwise against Kernel::lj).
#include <cuda_runtime.h>

#include <CLI/CLI.hpp>
#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "raycut/cuda/pairs.cuh"
#include "raycut/engine.hpp"
#include "raycut/kernels.hpp"
#include "raycut/tools/device_array.hpp"
#include "raycut/tools/generators.hpp"
#include "raycut/tools/system_info.hpp"

namespace neighbour_bench {

// The built-in Lennard-Jones energy (raycut::LennardJonesKernel), written as a user would: the
// same instructions, so functor_lj against lj measures the cost of the user-functor path.
struct UserLennardJones {
  using Accumulator = float;
  using options =
      raycut::functor_options<raycut::option::vanishes_at_infinity, raycut::option::combine>;
  float sigma6;
  float four_epsilon_sigma6;
  float* energy;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, raycut::Vec3, float r2) const {
    const float t = raycut::fast_reciprocal(r2);
    const float w = t * t * t;
    acc += w * (sigma6 * w - 1.0f);
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const {
    energy[i] = acc * four_epsilon_sigma6;
  }
};

static_assert(raycut::vanishes_at_infinity<UserLennardJones>::value &&
                  raycut::has_combine<UserLennardJones>::value,
              "the functor must take the built-in LJ's traversal paths");

}  // namespace neighbour_bench

namespace {

void check_cuda(cudaError_t e, const char* what) {
  if (e != cudaSuccess) throw std::runtime_error(std::string(what) + ": " + cudaGetErrorString(e));
}

// A device float array the functor writes (its own output, not the engine's).
class DeviceFloats {
 public:
  DeviceFloats() = default;
  DeviceFloats(const DeviceFloats&) = delete;
  DeviceFloats& operator=(const DeviceFloats&) = delete;
  ~DeviceFloats() {
    if (data_) cudaFree(data_);
  }
  float* ensure(std::size_t n) {
    if (n > size_) {
      if (data_) check_cuda(cudaFree(data_), "cudaFree");
      data_ = nullptr;
      size_ = 0;
      check_cuda(cudaMalloc(&data_, std::max<std::size_t>(n, 1) * sizeof(float)),
                 "cudaMalloc (functor output)");
      size_ = n;
    }
    return data_;
  }
  float* data() const { return data_; }

 private:
  float* data_ = nullptr;
  std::size_t size_ = 0;
};

enum class Op {
  build,
  count,
  list_full,
  list_half,
  list_full_dv,
  padded,
  lj,
  lj_forces,
  functor_lj,
  list_only_full,
  list_full_s,
  list_half_s,
  list_half_any_s,
  lj_forces_only
};
const std::vector<std::pair<std::string, Op>> kOps = {{"build", Op::build},
                                                      {"count", Op::count},
                                                      {"list_full", Op::list_full},
                                                      {"list_half", Op::list_half},
                                                      {"list_full_dv", Op::list_full_dv},
                                                      {"padded", Op::padded},
                                                      {"lj", Op::lj},
                                                      {"lj_forces", Op::lj_forces},
                                                      {"functor_lj", Op::functor_lj},
                                                      {"list_only_full", Op::list_only_full},
                                                      {"list_full_s", Op::list_full_s},
                                                      {"list_half_s", Op::list_half_s},
                                                      {"list_half_any_s", Op::list_half_any_s},
                                                      {"lj_forces_only", Op::lj_forces_only}};
// What runs by default: every operation of the first ten on the open inputs (the rows measured
// before the periodic ones), these on the periodic ones.
const std::vector<Op> kOpenOps = {Op::build,        Op::count,         Op::list_full, Op::list_half,
                                  Op::list_full_dv, Op::padded,        Op::lj,        Op::lj_forces,
                                  Op::functor_lj,   Op::list_only_full};
const std::vector<Op> kLiquidOps = {Op::build,          Op::count,     Op::list_full_s,
                                    Op::list_half_s,    Op::lj_forces, Op::lj_forces_only,
                                    Op::list_half_any_s};
const std::vector<Op> kBatchOps = {Op::build, Op::count, Op::list_full_s};

Op parse_op(const std::string& name) {
  for (const auto& [n, op] : kOps)
    if (n == name) return op;
  std::string known;
  for (const auto& [n, op] : kOps) known += (known.empty() ? "" : ", ") + n;
  throw std::invalid_argument("unknown operation '" + name + "' (known: " + known + ")");
}

struct Options {
  std::vector<std::string> methods = {"grid", "grid-paper"};
  std::vector<int> betas = {16, 32};
  std::vector<int> ps = {1, 2, 4, 8, 16, 32};
  std::vector<std::string> ops;  // empty: all
  std::vector<std::string> modes = {"cold", "prepared"};
  int reps = 5;
  bool lj_liquid = false;
  bool periodic = false;
  std::vector<int> periodic_n = {1 << 20};  // the periodic liquid's sizes
  bool no_suite = false;
  bool own_stream = false;
  double padded_factor = 1.25;
  std::uint64_t seed = 1;
  std::string out;
};

struct Input {
  std::string suite;  // uniform, lj-liquid, lj-liquid-pbc or batch-pbc
  int param = 0, p = 0;
  raycut::PointCloud cloud;
  raycut::Systems systems;  // plain for the open inputs
};

// The LJ liquid of docs/benchmarks.md without periodicity: 2^20 particles uniform in a
// cube of side (N / 0.8442)^(1/3), rc = 2.5 (the suite's generator, scaled: deterministic).
Input lj_liquid(std::uint64_t seed) {
  const int n = 1 << 20;
  Input in{"lj-liquid", 0, 0, raycut::uniform_suite(1, n, seed), {}};
  const float side = static_cast<float>(std::cbrt(n / 0.8442));
  for (float& x : in.cloud.xyz) x *= side;
  in.cloud.cutoff = 2.5f;
  in.cloud.name = "lj-liquid N=2^20 density 0.8442 rc 2.5 (not periodic)";
  return in;
}

// `systems` periodic cubes of `per_system` particles at density 0.8442, rc = 2.5, as one input:
// one system (no offsets) when systems == 1, else a batch sharing one box. Positions uniform in
// [0, side)^3 of each system (the suite's generator, scaled; its streams are per particle, so
// each run of per_system particles is an independent uniform sample).
Input periodic_liquid(std::string suite, int systems, int per_system, std::uint64_t seed) {
  const std::size_t n = static_cast<std::size_t>(systems) * per_system;
  Input in{std::move(suite),
           systems,
           per_system,
           raycut::uniform_suite(1, static_cast<int>(n), seed),
           {}};
  const double side = std::cbrt(per_system / 0.8442);
  for (float& x : in.cloud.xyz) x = static_cast<float>(x * side);
  in.cloud.cutoff = 2.5f;
  in.systems.box = raycut::Box::orthorhombic(side, side, side);
  if (systems > 1)
    for (int s = 0; s <= systems; ++s)
      in.systems.offsets.push_back(static_cast<std::uint64_t>(s) * per_system);
  char name[128];
  std::snprintf(name, sizeof name, "%s %d x %d, periodic cube side %.3f, rc 2.5", in.suite.c_str(),
                systems, per_system, side);
  in.cloud.name = name;
  return in;
}

double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const std::size_t m = v.size() / 2;
  return v.size() % 2 ? v[m] : 0.5 * (v[m - 1] + v[m]);
}

// What one timed operation holds: the engine (owned, or the shared built one of list_only_full)
// and the result buffers.
struct State {
  std::unique_ptr<raycut::Engine> owned;
  raycut::Engine* engine = nullptr;
  raycut::NeighbourListBuffer list;
  raycut::PaddedNeighbourBuffer padded;
  DeviceFloats energy;
  raycut::PaddedReport report;
  bool built = false;  // the engine was built outside the timing (prepare())
};

struct Context {
  std::string method;
  raycut::PositionsView positions;
  const raycut::Systems* systems = nullptr;  // null or plain: the two-argument build
  float cutoff = 0;
  std::uint32_t k = 1;  // padded width
  cudaStream_t stream = nullptr;
  raycut::Engine* built = nullptr;  // for list_only_full
};

void make_engine(State& s, const Context& c) {
  s.owned = std::make_unique<raycut::Engine>(c.method);
  if (c.stream) s.owned->set_stream(c.stream);
  s.engine = s.owned.get();
}

// Open inputs keep the two-argument build their rows were measured with.
void build(raycut::Engine& e, const Context& c) {
  if (c.systems && !c.systems->plain())
    e.build(c.positions, c.cutoff, *c.systems);
  else
    e.build(c.positions, c.cutoff);
}

// Operations timed on an engine built before the timing (by prepare()).
bool prebuilt(Op op) {
  return op == Op::lj_forces_only;
}

// Outside the timing: the built engine of a compute-alone operation (once per prepared state).
void prepare(Op op, State& s, const Context& c) {
  if (!prebuilt(op) || s.built) return;
  if (!s.engine) make_engine(s, c);
  build(*s.engine, c);
  s.built = true;
}

// The operation itself: everything between the two events.
void execute(Op op, State& s, const Context& c) {
  if (op == Op::list_only_full) {
    s.engine = c.built;
    s.engine->neighbours(s.list);
    return;
  }
  if (op == Op::lj_forces_only) {
    s.engine->run(raycut::Kernel::lj_forces);
    return;
  }
  if (!s.engine) make_engine(s, c);
  raycut::Engine& e = *s.engine;
  build(e, c);
  switch (op) {
    case Op::build:
      break;
    case Op::count:
      e.run(raycut::Kernel::count);
      break;
    case Op::list_full:
      e.neighbours(s.list);
      break;
    case Op::list_half:
      e.neighbours(s.list, raycut::ListOptions{true, false, false});
      break;
    case Op::list_full_dv:
      e.neighbours(s.list, raycut::ListOptions{false, true, true});
      break;
    case Op::padded:
      s.report = e.padded_neighbours(s.padded, {.k = c.k});
      break;
    case Op::lj:
      e.run(raycut::Kernel::lj);
      break;
    case Op::lj_forces:
      e.run(raycut::Kernel::lj_forces);
      break;
    case Op::functor_lj: {
      // As the built-in with eps = sigma = 1 (KernelOptions' defaults).
      float* out = s.energy.ensure(e.size());
      raycut::cuda::for_each_pair(e, neighbour_bench::UserLennardJones{1.0f, 4.0f, out}, c.stream);
      break;
    }
    case Op::list_full_s: {
      raycut::ListOptions lo;
      lo.shifts = true;
      e.neighbours(s.list, lo);
      break;
    }
    case Op::list_half_s:
    case Op::list_half_any_s: {
      raycut::ListOptions lo;
      lo.half = true;
      lo.any_row = op == Op::list_half_any_s;
      lo.shifts = true;
      e.neighbours(s.list, lo);
      break;
    }
    case Op::list_only_full:
    case Op::lj_forces_only:
      break;
  }
}

struct Measurement {
  std::vector<double> events, host, engine_build, engine_compute;
  std::uint64_t entries = 0;
  std::size_t bytes = 0;
  raycut::PaddedReport report;
  bool has_entries = false;
  std::string check = "-";
};

// The functor's energies against Kernel::lj's: "bitwise", "close" (every value within 1e-3
// relative, the summation order of a rebuilt structure may differ) or DIFFERS.
std::string compare_energies(const std::vector<float>& got, const std::vector<float>& want) {
  if (got.size() != want.size()) return "DIFFERS(size)";
  if (got.empty() || std::memcmp(got.data(), want.data(), got.size() * sizeof(float)) == 0)
    return "bitwise";
  std::size_t bad = 0;
  for (std::size_t i = 0; i < got.size(); ++i) {
    const double a = got[i], b = want[i];
    if (std::isfinite(a) != std::isfinite(b)) {
      ++bad;
    } else if (std::isfinite(a)) {
      if (std::abs(a - b) > 1e-3 * std::max({std::abs(a), std::abs(b), 1.0})) ++bad;
    } else if (!(a == b) && !(std::isnan(a) && std::isnan(b))) {
      ++bad;
    }
  }
  return bad ? "DIFFERS(" + std::to_string(bad) + " targets)" : "close";
}

bool uses_run(Op op) {
  return op == Op::count || op == Op::lj || op == Op::lj_forces || op == Op::lj_forces_only;
}

// One warm-up, then `reps` timed repetitions of `op` in `mode`.
Measurement measure(Op op, bool cold, int reps, const Context& c,
                    const std::vector<float>& reference_energy, std::uint64_t pairs) {
  Measurement m;
  cudaEvent_t start, stop;
  check_cuda(cudaEventCreate(&start), "cudaEventCreate");
  check_cuda(cudaEventCreate(&stop), "cudaEventCreate");
  std::optional<State> prepared;
  if (!cold) {
    prepared.emplace();
    if (op != Op::list_only_full) make_engine(*prepared, c);
  }
  for (int r = -1; r < reps; ++r) {
    std::optional<State> fresh;
    // A compute-alone operation's engine is built here, outside the timing (cold: a fresh one).
    if (prebuilt(op)) prepare(op, cold ? fresh.emplace() : *prepared, c);
    check_cuda(cudaDeviceSynchronize(), "cudaDeviceSynchronize");
    const auto t0 = std::chrono::steady_clock::now();
    check_cuda(cudaEventRecord(start, c.stream), "cudaEventRecord");
    // cold: construction inside the timing
    State& s = !cold ? *prepared : fresh ? *fresh : fresh.emplace();
    execute(op, s, c);
    check_cuda(cudaEventRecord(stop, c.stream), "cudaEventRecord");
    check_cuda(cudaEventSynchronize(stop), "cudaEventSynchronize");
    const auto t1 = std::chrono::steady_clock::now();
    check_cuda(cudaGetLastError(), "kernel");
    float ms = 0;
    check_cuda(cudaEventElapsedTime(&ms, start, stop), "cudaEventElapsedTime");
    if (r == reps - 1) {  // what the result holds, from the last repetition
      switch (op) {
        case Op::list_full:
        case Op::list_only_full:
        case Op::list_full_dv:
        case Op::list_half:
        case Op::list_full_s:
        case Op::list_half_s:
        case Op::list_half_any_s: {
          m.entries = s.list.pairs();
          m.bytes = s.list.bytes();
          m.has_entries = true;
          // A half list holds one of (i, j, S) and (j, i, -S), self-images (i, i, +-S) included.
          // With images the two orientations are two different float differences (the target
          // minus another point's image), so a pair within float rounding of the cutoff may be
          // in one and out of the other: the band of docs/limits.md, either answer exact. At 2^22
          // such pairs exist (1 in 231,729,614 in a run on the H200, 2026-12-02): a half list may
          // differ from half the pairs by at most the pairs within a few ulps of the cutoff, 1e-6
          // of them here.
          const bool half =
              op == Op::list_half || op == Op::list_half_s || op == Op::list_half_any_s;
          const std::uint64_t want = half ? pairs / 2 : pairs;
          const std::uint64_t off =
              2 * m.entries > pairs ? 2 * m.entries - pairs : pairs - 2 * m.entries;
          const bool band = half && !c.systems->plain() && off <= pairs / 1000000;
          m.check = m.entries == want ? "ok"
                    : band            ? "ok(band " + std::to_string(off) + ")"
                                      : "MISMATCH";
          const bool shifts =
              op == Op::list_full_s || op == Op::list_half_s || op == Op::list_half_any_s;
          if (shifts && m.entries > 0 && s.list.shifts() == nullptr)
            m.check = "MISMATCH(no shifts)";
          break;
        }
        case Op::padded: {
          m.report = s.report;
          m.bytes = s.padded.size() * (std::size_t{s.padded.width()} + 1) * sizeof(std::uint32_t);
          // Overflow is reported, not an error; the report must agree with itself.
          const bool consistent =
              (s.report.overflowed_rows == 0) == (s.report.largest_count <= s.padded.width());
          m.check = consistent ? "ok" : "MISMATCH";
          break;
        }
        case Op::functor_lj: {
          const std::size_t n = s.engine->size();
          m.bytes = n * sizeof(float);
          std::vector<float> got(n);
          if (n)
            check_cuda(
                cudaMemcpy(got.data(), s.energy.data(), n * sizeof(float), cudaMemcpyDeviceToHost),
                "cudaMemcpy");
          m.check = compare_energies(got, reference_energy);
          break;
        }
        default:
          break;
      }
    }
    if (r >= 0) {
      m.events.push_back(ms);
      m.host.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
      if (op != Op::list_only_full) {
        const raycut::Timings& t = s.engine->last_timings();
        if (!prebuilt(op)) m.engine_build.push_back(t.device_build_ms);
        if (uses_run(op)) m.engine_compute.push_back(t.device_compute_ms);
      }
    }
    // A cold state is destroyed here, outside the timing.
  }
  cudaEventDestroy(start);
  cudaEventDestroy(stop);
  return m;
}

std::string no_commas(std::string s) {
  std::replace(s.begin(), s.end(), ',', ';');
  return s;
}

std::string fmt(double v) {
  if (std::isnan(v)) return "";
  char b[32];
  std::snprintf(b, sizeof b, "%.4f", v);
  return b;
}

int run(const Options& o) {
  std::vector<Op> asked;  // empty: each input's default operations
  for (const auto& name : o.ops) asked.push_back(parse_op(name));
  std::vector<bool> modes;  // cold?
  for (const auto& m : o.modes) {
    if (m == "cold")
      modes.push_back(true);
    else if (m == "prepared")
      modes.push_back(false);
    else
      throw std::invalid_argument("unknown mode '" + m + "' (cold, prepared)");
  }
  if (!raycut::cuda_device_available()) {
    std::fprintf(stderr, "neighbour_bench: no usable CUDA device\n");
    return 1;
  }
  const raycut::SystemInfo sys = raycut::system_info();
  const std::string env =
      no_commas(sys.gpu) + "," + no_commas(sys.driver) + "," + no_commas(sys.cuda);

  // The CSV goes to a temporary file, renamed over --out once complete (a failed run leaves the
  // .tmp with the rows so far).
  const std::string tmp = o.out.empty() ? "" : o.out + ".tmp";
  std::ofstream csv;
  if (!tmp.empty()) {
    csv.open(tmp, std::ios::out | std::ios::trunc);
    if (!csv) throw std::runtime_error(tmp + ": cannot open for writing");
    csv << "suite,param,p,method,N,cutoff,operation,mode,ms,min,max,host_ms,engine_build_ms,"
           "engine_compute_ms,pairs,entries,bytes,k,overflowed_rows,largest_count,check,reps,"
           "gpu,driver,cuda\n";
  }

  cudaStream_t stream = nullptr;
  if (o.own_stream) check_cuda(cudaStreamCreateWithFlags(&stream, cudaStreamNonBlocking), "stream");

  std::vector<std::pair<std::string, std::pair<int, int>>> configs;  // suite, (param, p)
  if (!o.no_suite)
    for (int beta : o.betas)
      for (int p : o.ps) configs.push_back({"uniform", {beta, p}});
  if (o.lj_liquid) configs.push_back({"lj-liquid", {0, 0}});
  if (o.periodic) {  // (systems, particles per system)
    for (int n : o.periodic_n) configs.push_back({"lj-liquid-pbc", {1, n}});
    configs.push_back({"batch-pbc", {512, 128}});
    configs.push_back({"batch-pbc", {64, 4096}});
  }

  std::printf(
      "neighbour_bench on %s (driver %s, CUDA %s), %d reps, %s stream; ms = CUDA-event "
      "median\n",
      sys.gpu.c_str(), sys.driver.c_str(), sys.cuda.c_str(), o.reps,
      stream ? "own non-blocking" : "legacy default");
  std::printf("%-9s %5s %3s %9s %-17s %-14s %10s %10s %12s %s\n", "suite", "param", "p", "N",
              "method", "operation", "cold ms", "prep ms", "entries", "check");
  int failures = 0;
  for (const auto& [suite, pp] : configs) {
    const Input in = suite == "uniform"     ? Input{"uniform",
                                                pp.first,
                                                pp.second,
                                                raycut::uniform_suite(pp.first, pp.second, o.seed),
                                                {}}
                     : suite == "lj-liquid" ? lj_liquid(o.seed)
                                            : periodic_liquid(suite, pp.first, pp.second, o.seed);
    const std::vector<Op>& ops = !asked.empty()             ? asked
                                 : suite == "lj-liquid-pbc" ? kLiquidOps
                                 : suite == "batch-pbc"     ? kBatchOps
                                                            : kOpenOps;
    const std::size_t n = in.cloud.size();
    if (!in.systems.plain()) std::printf("# %s\n", in.cloud.name.c_str());
    const raycut::DeviceArray positions(in.cloud.xyz);
    for (const auto& method : o.methods) {
      Context c;
      c.method = method;
      c.positions = positions.view();
      c.systems = &in.systems;
      c.cutoff = in.cloud.cutoff;
      c.stream = stream;
      std::uint64_t pairs = 0;
      std::vector<float> reference_energy;
      std::unique_ptr<raycut::Engine> built;
      try {
        built = std::make_unique<raycut::Engine>(method);
        if (stream) built->set_stream(stream);
        build(*built, c);
        for (auto v : built->compute(raycut::Kernel::count).count) pairs += v;
        // Only the functor's check needs it (a method may refuse lj elsewhere).
        if (std::find(ops.begin(), ops.end(), Op::functor_lj) != ops.end())
          reference_energy = built->compute(raycut::Kernel::lj).energy;
      } catch (const std::exception& e) {
        std::fprintf(stderr, "  %s N=%zu %s: skipped: %s\n", suite.c_str(), n, method.c_str(),
                     e.what());
        continue;
      }
      c.built = built.get();
      const double mean = n ? static_cast<double>(pairs) / n : 0.0;
      c.k = static_cast<std::uint32_t>(std::max(1.0, std::ceil(o.padded_factor * mean)));
      for (Op op : ops) {
        const std::string op_name =
            std::find_if(kOps.begin(), kOps.end(), [&](auto& x) { return x.second == op; })->first;
        double shown[2] = {NAN, NAN};
        std::string entries_shown = "", check_shown = "";
        for (bool cold : modes) {
          Measurement m;
          try {
            m = measure(op, cold, o.reps, c, reference_energy, pairs);
          } catch (const std::exception& e) {
            std::fprintf(stderr, "  %s N=%zu %s %s %s: skipped: %s\n", suite.c_str(), n,
                         method.c_str(), op_name.c_str(), cold ? "cold" : "prepared", e.what());
            cudaGetLastError();  // a refusal, not a sticky error, is what we go on from
            continue;
          }
          if (m.check.rfind("MISMATCH", 0) == 0 || m.check.rfind("DIFFERS", 0) == 0) ++failures;
          shown[cold ? 0 : 1] = median(m.events);
          if (m.has_entries) entries_shown = std::to_string(m.entries);
          if (op == Op::padded)
            entries_shown =
                "K=" + std::to_string(c.k) + " ovf " + std::to_string(m.report.overflowed_rows);
          check_shown = m.check;
          if (csv.is_open()) {
            csv << suite << ',' << in.param << ',' << in.p << ',' << method << ',' << n << ','
                << in.cloud.cutoff << ',' << op_name << ',' << (cold ? "cold" : "prepared") << ','
                << fmt(median(m.events)) << ','
                << fmt(*std::min_element(m.events.begin(), m.events.end())) << ','
                << fmt(*std::max_element(m.events.begin(), m.events.end())) << ','
                << fmt(median(m.host)) << ',' << fmt(median(m.engine_build)) << ','
                << fmt(median(m.engine_compute)) << ',' << pairs << ','
                << (m.has_entries ? std::to_string(m.entries) : "") << ',' << m.bytes << ','
                << (op == Op::padded ? std::to_string(c.k) : "") << ','
                << (op == Op::padded ? std::to_string(m.report.overflowed_rows) : "") << ','
                << (op == Op::padded ? std::to_string(m.report.largest_count) : "") << ','
                << m.check << ',' << m.events.size() << ',' << env << '\n';
            csv.flush();
            if (!csv) throw std::runtime_error(tmp + ": write failed");
          }
        }
        std::printf("%-9s %5d %3d %9zu %-17s %-14s %10s %10s %12s %s\n", suite.c_str(), in.param,
                    in.p, n, method.c_str(), op_name.c_str(), fmt(shown[0]).c_str(),
                    fmt(shown[1]).c_str(), entries_shown.c_str(), check_shown.c_str());
        std::fflush(stdout);
      }
    }
  }
  if (stream) cudaStreamDestroy(stream);
  if (csv.is_open()) {
    csv.close();
    if (!csv) throw std::runtime_error(tmp + ": write failed");
    if (std::rename(tmp.c_str(), o.out.c_str()) != 0)
      throw std::runtime_error("cannot rename " + tmp + " to " + o.out + ": " +
                               std::strerror(errno));
    std::printf("wrote %s\n", o.out.c_str());
  }
  if (failures) std::fprintf(stderr, "neighbour_bench: %d result check(s) failed\n", failures);
  return failures ? 1 : 0;
}

}  // namespace

int main(int argc, char** argv) {
  Options o;
  CLI::App app{
      "Neighbour lists vs fused kernels: CUDA-event medians, cold and prepared "
      "(docs/benchmarks.md)"};
  app.add_option("--methods", o.methods, "Engine methods (default grid,grid-paper)")
      ->delimiter(',');
  app.add_option("--betas", o.betas, "Uniform suite beta values (default 16,32)")
      ->delimiter(',')
      ->check(CLI::PositiveNumber);
  app.add_option("--ps", o.ps, "Uniform suite p values (default 1,2,4,8,16,32)")
      ->delimiter(',')
      ->check(CLI::PositiveNumber);
  app.add_option("--ops", o.ops,
                 "Operations (default: each input's own; the open ones all of build,count,"
                 "list_full,list_half,list_full_dv,padded,lj,lj_forces,functor_lj,list_only_full; "
                 "also list_full_s,list_half_s,lj_forces_only)")
      ->delimiter(',');
  app.add_option("--modes", o.modes, "cold and/or prepared (default both)")->delimiter(',');
  app.add_option("--reps", o.reps, "Timed repetitions after one warm-up (>= 5 for the protocol)")
      ->check(CLI::Range(1, 1000));
  app.add_flag("--lj-liquid", o.lj_liquid,
               "Also the LJ liquid: N = 2^20, density 0.8442, rc 2.5, not periodic");
  app.add_flag("--periodic", o.periodic,
               "Also the periodic workloads: the LJ liquid in a periodic cube (2^20), batches of "
               "512 x 128 and 64 x 4096 periodic cubes; lists with shifts, lj_forces");
  app.add_option("--periodic-n", o.periodic_n,
                 "The periodic liquid's sizes (default 1048576: 2^20; 4194304 is ncu's 2^22)")
      ->delimiter(',')
      ->check(CLI::PositiveNumber);
  app.add_flag("--no-suite", o.no_suite,
               "Skip the uniform suite (with --lj-liquid / --periodic: only those)");
  app.add_flag("--stream", o.own_stream,
               "Run on an own non-blocking stream (default: the legacy default stream)");
  app.add_option("--padded-factor", o.padded_factor, "K = ceil(factor x mean count)")
      ->check(CLI::PositiveNumber);
  app.add_option("--seed", o.seed, "Seed of the inputs (raycut bench uses 1)");
  app.add_option("--out", o.out, "CSV file (written to FILE.tmp, renamed when complete)");
  CLI11_PARSE(app, argc, argv);
  try {
    return run(o);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "neighbour_bench: %s\n", e.what());
    return 2;
  }
}
