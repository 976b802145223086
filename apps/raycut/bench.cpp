// raycut bench: the timing protocol of spec/BENCHMARKS.md. Positions start where the method
// works (device for GPU methods, uploaded untimed); one warm-up, then `reps` timed build+compute;
// medians (min/max of total) per phase, one CSV row per timer (host clock, CUDA events).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <optional>

#include "commands.hpp"
#include "raycut/engine.hpp"
#include "raycut/generators.hpp"

namespace raycut::cli {
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
};

struct Samples {
  std::vector<double> build, compute, total;
  void add(double b, double c) {
    build.push_back(b);
    compute.push_back(c);
    total.push_back(b + c);
  }
};

int run_bench(const BenchOptions& o) {
  const auto methods = resolve_methods(o.methods);
  const Kernel kernel = parse_kernel(o.kernel);
  std::vector<int> params = o.params;
  if (params.empty())
    params = o.suite == "uniform" ? std::vector<int>{2, 4, 8, 16, 32}
                                  : std::vector<int>{2, 4, 8, 16, 32, 64, 128};
  const SystemInfo sys = system_info();
  const std::string gpu = sys.gpu == "none" ? "cpu: " + sys.cpu : sys.gpu;

  std::ofstream csv(o.out);
  if (!csv) throw Error(ErrorCode::io, o.out + ": cannot open for writing");
  csv << "suite,method,param,p,N,cutoff,pairs,build_ms,compute_ms,total_ms,total_ms_min,"
         "total_ms_max,reps,timer,gpu,driver,cuda,optix\n";
  std::fprintf(stderr, "raycut bench: %s suite, kernel %s, %d reps, on %s -> %s\n", o.suite.c_str(),
               o.kernel.c_str(), o.reps, gpu.c_str(), o.out.c_str());

  std::size_t configs = 0, done = 0;
  for (int param : params)
    for (int p : o.ps)
      if (o.max_n == 0 || suite_size(param, p) <= o.max_n) ++configs;

  for (int param : params) {
    for (int p : o.ps) {
      if (o.max_n != 0 && suite_size(param, p) > o.max_n) continue;
      const PointCloud cloud = suite_cloud(o.suite, param, p, o.seed);
      std::optional<DevicePositions> on_device;
      for (const auto& method : methods) {
        Engine engine(method);
        PositionsView view{cloud.xyz.data(), cloud.size(), MemorySpace::host};
        if (engine.space() == MemorySpace::device) {
          if (!on_device) on_device.emplace(cloud.xyz);
          view = on_device->view();
        }
        engine.build(view, cloud.cutoff);  // warm-up, and the pair count
        const auto counts = engine.compute(Kernel::count).count;
        std::uint64_t pairs = 0;
        for (auto c : counts) pairs += c;
        engine.run(kernel);

        Samples host, events;
        for (int r = 0; r < o.reps; ++r) {
          engine.build(view, cloud.cutoff);
          engine.run(kernel);
          const Timings& t = engine.last_timings();
          host.add(t.build_ms, t.compute_ms);
          if (t.device_build_ms >= 0) events.add(t.device_build_ms, t.device_compute_ms);
        }
        auto row = [&](const Samples& s, const char* timer) {
          if (s.total.empty()) return;
          char line[512];
          std::snprintf(line, sizeof line,
                        "%s,%s,%d,%d,%zu,%.9g,%llu,%.4f,%.4f,%.4f,%.4f,%.4f,%d,%s,%s,%s,%s,%s\n",
                        o.suite.c_str(), method.c_str(), param, p, cloud.size(), cloud.cutoff,
                        static_cast<unsigned long long>(pairs), median(s.build), median(s.compute),
                        median(s.total), *std::min_element(s.total.begin(), s.total.end()),
                        *std::max_element(s.total.begin(), s.total.end()), o.reps, timer,
                        gpu.c_str(), sys.driver.c_str(), sys.cuda.c_str(), sys.optix.c_str());
          csv << line;
        };
        row(host, "host");
        row(events, "events");
        csv.flush();
        std::fprintf(stderr, "  [%zu/%zu] %s param=%d p=%d N=%zu %s: total %.3f ms (median)\n",
                     done + 1, configs, o.suite.c_str(), param, p, cloud.size(), method.c_str(),
                     median(host.total));
      }
      ++done;
    }
  }
  return 0;
}

}  // namespace

Command add_bench(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "bench", "Run a benchmark suite of the paper (spec/BENCHMARKS.md) and write CSV");
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
      ->check(CLI::PositiveNumber);
  cmd->add_option("--p", o->ps, "Mean particles per cell (default 1,2,4,8,16,32)")
      ->delimiter(',')
      ->check(CLI::PositiveNumber);
  cmd->add_option("-k,--kernel", o->kernel, "count, lj or smooth")
      ->check(CLI::IsMember({"count", "lj", "smooth"}));
  cmd->add_option("-r,--reps", o->reps, "Timed repetitions after one warm-up")
      ->check(CLI::Range(1, 1000));
  cmd->add_option("--max-n", o->max_n, "Skip configurations with more particles than this");
  cmd->add_option("-o,--out", o->out, "CSV file to write");
  cmd->add_option("--seed", o->seed, "Random seed");
  return [o] { return run_bench(*o); };
}

}  // namespace raycut::cli
