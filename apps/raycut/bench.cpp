// raycut bench: the timing protocol of docs/benchmarks.md. Positions start where the method
// works (device for GPU methods, uploaded untimed); one warm-up, then `reps` timed build+compute;
// medians (min/max of total) per phase, one CSV row per timer (host clock, CUDA events). With
// --cell/--pbc every build is in that periodic box, and the suite column says "-periodic".
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <sstream>

#include <unistd.h>

#include "commands.hpp"
#include "raycut/engine.hpp"
#include "raycut/tools/device_array.hpp"
#include "raycut/tools/files.hpp"
#include "raycut/tools/generators.hpp"

namespace raycut::cli {

std::string environment_columns(const SystemInfo& sys, bool with_optix) {
  const std::string gpu = sys.gpu == "none" ? "cpu: " + sys.cpu : sys.gpu;
  return gpu + "," + sys.driver + "," + sys.cuda + "," + (with_optix ? sys.optix : "none");
}

namespace {

struct BenchOptions {
  std::string suite = "uniform";
  std::vector<std::string> methods = {"default"};
  std::vector<int> params;  // beta or alpha; empty = the suite's list
  std::vector<int> ps = {1, 2, 4, 8, 16, 32};
  std::string kernel = "lj";
  int reps = 5;
  std::size_t max_n = 0;  // 0 = no limit
  std::string out = "bench.csv";
  std::uint64_t seed = 1;
  std::string paper_binary;  // the paper's cudaLJ, run after ours, its rows merged
  bool quiet = false;        // no per-configuration lines on stderr
  std::size_t large_n = 0;   // above this many particles (0: never) ...
  int large_reps = 2;        // ... time this many repetitions instead (the CSV says how many)
  BoxOptions box_options;
  Box box;  // resolved from box_options
#if defined(RAYCUT_CLI_MPI)
  DistributedBenchOptions distributed;
#endif
  // The suite column: the suite's name, with "-periodic" in a periodic box, so that rows of
  // both never mix under one name.
  std::string suite_column() const {
    return box.periodic() ? suite + "-periodic" : suite;
  }
};

struct Samples {
  std::vector<double> build, compute, total;
  void add(double b, double c) {
    build.push_back(b);
    compute.push_back(c);
    total.push_back(b + c);
  }
};

// Runs the paper's own CUDA grid (Cuda-version/cudaLJ.cu of berenger-eu/particle-interaction-
// with-optix, built by the user) in a scratch folder and turns its results-*.csv (one line per
// repetition, seconds, host clock) into rows of method paper-cudaLJ: medians per configuration.
// It always runs its whole suite; its pair counts are candidates, not pairs, so `pairs` is empty.
std::vector<std::string> run_paper_binary(const std::string& binary, const std::string& suite,
                                          const std::string& environment) {
  namespace fs = std::filesystem;
  const fs::path exe = fs::absolute(binary);
  if (!fs::is_regular_file(exe)) throw Error(ErrorCode::io, binary + ": no such file");
  const fs::path dir = fs::temp_directory_path() / ("raycut-paper-" + std::to_string(::getpid()));
  fs::remove_all(dir);
  fs::create_directories(dir);
  const std::string command = "cd '" + dir.string() + "' && '" + exe.string() + "'" +
                              (suite == "surface" ? " -gs" : "") + " > run.log 2>&1";
  std::fprintf(stderr, "  running the paper's binary: %s\n", command.c_str());
  if (std::system(command.c_str()) != 0)
    throw Error(ErrorCode::backend,
                binary + " failed; its output is in " + (dir / "run.log").string());
  fs::path results;
  for (const auto& entry : fs::directory_iterator(dir))
    if (entry.path().filename().string().rfind("results", 0) == 0) results = entry.path();
  if (results.empty())
    throw Error(ErrorCode::io, binary + " wrote no results-*.csv in " + dir.string());

  // (boxDiv, N) -> per-repetition (init, compute) milliseconds.
  std::map<std::pair<int, std::size_t>, std::vector<std::pair<double, double>>> runs;
  io::LineReader in(results.string());
  std::string line;
  in.next(line);  // header
  while (in.next(line)) {
    std::vector<std::string> f;
    std::stringstream ss(line);
    for (std::string cell; std::getline(ss, cell, ',');) f.push_back(cell);
    if (f.size() < 10) continue;
    runs[{std::stoi(f[3]), std::stoull(f[0])}].emplace_back(std::stod(f[7]) * 1e3,
                                                            std::stod(f[8]) * 1e3);
  }
  std::vector<std::string> rows;
  for (const auto& [key, reps] : runs) {
    const auto [param, n] = key;
    const int p = static_cast<int>(n / suite_size(param, 1));
    const double cutoff = suite == "uniform"
                              ? 1.0 / param
                              : std::acos(std::clamp(1.0 - 2.0 * 9.0 * p / n, -1.0, 1.0));
    std::vector<double> build, compute, total;
    for (const auto& [b, c] : reps) {
      build.push_back(b);
      compute.push_back(c);
      total.push_back(b + c);
    }
    char row[512];
    std::snprintf(row, sizeof row,
                  "%s,paper-cudaLJ,%d,%d,%zu,%.9g,,%.4f,%.4f,%.4f,%.4f,%.4f,%zu,host,%s\n",
                  suite.c_str(), param, p, n, cutoff, median(build), median(compute), median(total),
                  *std::min_element(total.begin(), total.end()),
                  *std::max_element(total.begin(), total.end()), reps.size(), environment.c_str());
    rows.push_back(row);
  }
  fs::remove_all(dir);
  return rows;
}

// A configuration whose slowest repetition took this many times its fastest is reported noisy.
constexpr double noisy_spread = 1.5;

// Warm-up (and the pair count), then o.reps timed build + run (o.large_reps above o.large_n
// particles); returns one CSV row per timer, whose reps column says how many were timed (written
// by the caller, so that a failing output is not mistaken for a failing method).
std::string bench_method(const BenchOptions& o, const std::string& method, Kernel kernel,
                         const PointCloud& cloud, int param, int p,
                         std::optional<DeviceArray>& on_device, const std::string& environment) {
  std::string rows;
  Engine engine(method);
  PositionsView view{cloud.xyz.data(), cloud.size(), MemorySpace::host};
  if (engine.space() == MemorySpace::device) {
    if (!on_device) on_device.emplace(cloud.xyz);
    view = on_device->view();
  }
  // Open boxes take the plain build: the rows of an open run stay what they were.
  const auto build = [&] {
    if (o.box.periodic())
      engine.build(view, cloud.cutoff, o.box);
    else
      engine.build(view, cloud.cutoff);
  };
  build();
  const auto counts = engine.compute(Kernel::count).count;
  std::uint64_t pairs = 0;
  for (auto c : counts) pairs += c;
  engine.run(kernel);

  const int reps = o.large_n != 0 && cloud.size() > o.large_n ? o.large_reps : o.reps;
  Samples host, events;
  for (int r = 0; r < reps; ++r) {
    build();
    engine.run(kernel);
    const Timings& t = engine.last_timings();
    host.add(t.build_ms, t.compute_ms);
    if (t.device_build_ms >= 0) events.add(t.device_build_ms, t.device_compute_ms);
  }
  for (const auto& [samples, timer] : {std::pair{&host, "host"}, std::pair{&events, "events"}}) {
    const Samples& s = *samples;
    if (s.total.empty()) continue;
    char line[512];
    std::snprintf(
        line, sizeof line, "%s,%s,%d,%d,%zu,%.9g,%llu,%.4f,%.4f,%.4f,%.4f,%.4f,%d,%s,%s\n",
        o.suite_column().c_str(), method.c_str(), param, p, cloud.size(), cloud.cutoff,
        static_cast<unsigned long long>(pairs), median(s.build), median(s.compute), median(s.total),
        *std::min_element(s.total.begin(), s.total.end()),
        *std::max_element(s.total.begin(), s.total.end()), reps, timer, environment.c_str());
    rows += line;
  }
  std::fprintf(stderr, "      build %.3f + compute %.3f ms (host, median)\n", median(host.build),
               median(host.compute));
  // Lent machines have moments where one configuration runs several times slower: say so, so
  // that the row is rerun rather than believed.
  const double fastest = *std::min_element(host.total.begin(), host.total.end());
  const double slowest = *std::max_element(host.total.begin(), host.total.end());
  if (reps >= 3 && fastest > 0 && slowest > noisy_spread * fastest)
    std::fprintf(stderr,
                 "      warning: noisy: the slowest repetition took %.1fx the fastest; rerun this "
                 "configuration before trusting its median\n",
                 slowest / fastest);
  return rows;
}

int run_bench(BenchOptions& o) {
  o.box = resolve_box(o.box_options);
  if (o.box.periodic() && !o.paper_binary.empty())
    throw Error(ErrorCode::invalid_argument,
                "--paper-binary: the paper's grid has no periodic boxes; leave out --cell/--pbc");
  const auto methods = resolve_methods(o.methods);
  const Kernel kernel = parse_kernel(o.kernel);
  std::vector<int> params = o.params;
  if (params.empty())
    params = o.suite == "uniform" ? std::vector<int>{2, 4, 8, 16, 32}
                                  : std::vector<int>{2, 4, 8, 16, 32, 64, 128};
  const SystemInfo sys = system_info();
  const std::string environment = environment_columns(sys, true);
  const std::string gpu = environment.substr(0, environment.find(','));

  io::OutputFile csv(o.out);  // before the run: an unwritable path fails now, not at the end
  csv.write(
      "suite,method,param,p,N,cutoff,pairs,build_ms,compute_ms,total_ms,total_ms_min,"
      "total_ms_max,reps,timer,gpu,driver,cuda,optix\n");
  std::fprintf(stderr, "raycut bench: %s suite, kernel %s, %d reps, on %s -> %s\n", o.suite.c_str(),
               o.kernel.c_str(), o.reps, gpu.c_str(), o.out.c_str());
  if (o.box.periodic())
    std::fprintf(stderr, "  periodic box %s (suite column %s)\n", describe_box(o.box).c_str(),
                 o.suite_column().c_str());

  std::size_t configs = 0, done = 0;
  for (int param : params)
    for (int p : o.ps)
      if (o.max_n == 0 || suite_particles(param, p) <= o.max_n) ++configs;
  const Progress progress("bench", configs, o.quiet);  // the ETA of each configuration's line

  for (int param : params) {
    for (int p : o.ps) {
      if (o.max_n != 0 && suite_particles(param, p) > o.max_n) continue;
      // Host memory from below: positions and the pair counts, 16 bytes a particle (a GPU method's
      // structures are on the device, which the engine checks itself).
      const PointCloud cloud = suite_cloud(o.suite, param, p, o.seed, 16);
      std::optional<DeviceArray> on_device;
      for (const auto& method : methods) {
        std::string rows;
        try {
          rows = bench_method(o, method, kernel, cloud, param, p, on_device, environment);
        } catch (const Error& e) {  // e.g. a dense grid that does not fit: say so, go on
          if (!o.quiet)
            std::fprintf(stderr, "  [%zu/%zu] %s param=%d p=%d N=%zu %s: skipped: %s\n", done + 1,
                         configs, o.suite.c_str(), param, p, cloud.size(), method.c_str(),
                         e.what());
          continue;
        }
        csv.write(rows);
        csv.flush();  // into the temporary file: a run killed half-way keeps its rows there
        if (!o.quiet)
          std::fprintf(stderr, "  [%zu/%zu] %s param=%d p=%d N=%zu %s: done, %s\n", done + 1,
                       configs, o.suite.c_str(), param, p, cloud.size(), method.c_str(),
                       progress.eta(done + 1).c_str());
      }
      ++done;
    }
  }
  if (!o.paper_binary.empty()) {
    for (const auto& row :
         run_paper_binary(o.paper_binary, o.suite, environment_columns(sys, false)))
      csv.write(row);
  }
  csv.commit();
  std::fprintf(stderr, "wrote %s\n", o.out.c_str());
  return 0;
}

}  // namespace

Command add_bench(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "bench", "Run a benchmark suite of the paper (docs/benchmarks.md) and write CSV");
  auto o = std::make_shared<BenchOptions>();
  cmd->add_option("-s,--suite", o->suite, "uniform or surface")
      ->check(CLI::IsMember({"uniform", "surface"}));
  cmd->add_option(
         "-m,--methods", o->methods,
         "Methods (default = the available non-oracle methods, GPU ones only when there is a GPU)")
      ->delimiter(',');
  cmd->add_option("--param", o->params,
                  "beta (uniform; default 2,4,8,16,32) or alpha (surface; default 2..128)")
      ->delimiter(',')
      ->check(positive_integer());
  cmd->add_option("--p", o->ps, "Mean particles per cell (default 1,2,4,8,16,32)")
      ->delimiter(',')
      ->check(positive_integer());
  cmd->add_option("-k,--kernel", o->kernel, "count, lj, lj_forces or smooth")
      ->check(CLI::IsMember({"count", "lj", "lj_forces", "smooth"}));
  cmd->add_option("-r,--reps", o->reps, "Timed repetitions after one warm-up")
      ->check(CLI::Range(1, 1000));
  cmd->add_option("--max-n", o->max_n,
                  "Skip configurations with more particles than this (0, the default: no limit)")
      ->check(count_option());
  cmd->add_option("-o,--out", o->out, "CSV file to write");
  cmd->add_option("--seed", o->seed, "Random seed")->check(seed_option());
  cmd->add_flag("-q,--quiet", o->quiet, "No progress lines (with their ETA) on stderr");
  cmd->add_option(
         "--large-n", o->large_n,
         "Above this many particles, time --large-reps repetitions instead of --reps (0, the "
         "default: never)")
      ->check(count_option());
  cmd->add_option("--large-reps", o->large_reps, "Repetitions above --large-n")
      ->check(CLI::Range(1, 1000));
  cmd->add_option("--paper-binary", o->paper_binary,
                  "Path of the paper's cudaLJ (built by you from Cuda-version/cudaLJ.cu): run it "
                  "after ours and merge its rows as method paper-cudaLJ")
      ->check(CLI::ExistingFile);
  add_box_options(*cmd, o->box_options);
#if defined(RAYCUT_CLI_MPI)
  add_distributed_bench_options(*cmd, o->distributed);
  return [o] {
    if (o->distributed.enabled)
      return run_distributed_bench(o->distributed, o->methods, o->reps, o->seed, o->out);
    return run_bench(*o);
  };
#else
  return [o] { return run_bench(*o); };
#endif
}

}  // namespace raycut::cli
