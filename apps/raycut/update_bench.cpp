// raycut update-bench: moving particles. A random walk of `jitter` x cutoff per step on a suite
// configuration; each step times update() (refit or rebuild) and the kernel, once with refits
// (skin > 0) and once rebuilding every step (skin = 0), for each method. One CSV row per
// (method, policy) with medians over the steps.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <optional>

#include "commands.hpp"
#include "raycut/engine.hpp"
#include "raycut/tools/device_array.hpp"
#include "raycut/tools/files.hpp"
#include "raycut/tools/generators.hpp"

namespace raycut::cli {
namespace {

struct UpdateOptions {
  std::string suite = "uniform";
  std::vector<std::string> methods = {"default"};
  int param = 32, p = 8, steps = 20;
  float jitter = 0.01f, skin = 0.2f;  // in units of the cutoff
  std::string kernel = "lj", out = "update.csv";
};

int run_update_bench(const UpdateOptions& o) {
  const auto methods = resolve_methods(o.methods);
  const Kernel kernel = parse_kernel(o.kernel);
  io::OutputFile csv(o.out);  // before the run: an unwritable path fails now, not at the end
  // Host memory from below: the start positions and the moving copy, 24 bytes a particle (a GPU
  // method's structures are on the device, which the engine checks itself).
  const PointCloud start = suite_cloud(o.suite, o.param, o.p, 1, 24);
  const SystemInfo sys = system_info();
  csv.write(
      "suite,method,param,p,N,cutoff,skin,jitter,steps,refits,update_ms,compute_ms,"
      "total_ms,build_ms,gpu,driver,cuda,optix\n");
  for (const auto& method : methods) {
    for (float skin : {o.skin, 0.0f}) {
      Engine engine(method);
      engine.set_update_policy({skin * start.cutoff});
      std::vector<float> xyz = start.xyz;
      auto view_of = [&](std::optional<DeviceArray>& holder) {
        if (engine.space() == MemorySpace::host)
          return PositionsView{xyz.data(), start.size(), MemorySpace::host};
        holder.emplace(xyz);
        return holder->view();
      };
      std::optional<DeviceArray> on_device;
      engine.build(view_of(on_device), start.cutoff);
      engine.run(kernel);
      const double build_ms = engine.last_timings().build_ms;
      std::vector<double> update_ms, compute_ms;
      int refits = 0;
      std::uint64_t state = 0x9e3779b97f4a7c15ULL;
      for (int step = 0; step < o.steps; ++step) {
        for (float& x : xyz) {  // untimed: a deterministic random walk
          state = state * 6364136223846793005ULL + 1442695040888963407ULL;
          const float u = static_cast<float>(state >> 40) / static_cast<float>(1 << 24);
          x += (2 * u - 1) * o.jitter * start.cutoff;
        }
        engine.update(view_of(on_device));
        engine.run(kernel);
        const Timings& t = engine.last_timings();
        update_ms.push_back(t.build_ms);
        compute_ms.push_back(t.compute_ms);
        refits += t.refit;
      }
      char line[512];
      std::snprintf(line, sizeof line,
                    "%s,%s,%d,%d,%zu,%.9g,%g,%g,%d,%d,%.4f,%.4f,%.4f,%.4f,%s,%s,%s,%s\n",
                    o.suite.c_str(), method.c_str(), o.param, o.p, start.size(), start.cutoff, skin,
                    o.jitter, o.steps, refits, median(update_ms), median(compute_ms),
                    median(update_ms) + median(compute_ms), build_ms, sys.gpu.c_str(),
                    sys.driver.c_str(), sys.cuda.c_str(), sys.optix.c_str());
      csv.write(line);
      csv.flush();
      std::fprintf(stderr, "  %s skin=%g: %d/%d refits, update %.3f ms, compute %.3f ms\n",
                   method.c_str(), skin, refits, o.steps, median(update_ms), median(compute_ms));
    }
  }
  csv.commit();
  std::fprintf(stderr, "wrote %s\n", o.out.c_str());
  return 0;
}

}  // namespace

Command add_update_bench(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "update-bench", "Moving particles: update() by refit (skin > 0) against rebuild, per step");
  auto o = std::make_shared<UpdateOptions>();
  cmd->add_option("-s,--suite", o->suite, "uniform or surface")
      ->check(CLI::IsMember({"uniform", "surface"}));
  cmd->add_option("-m,--methods", o->methods, "Methods")->delimiter(',');
  cmd->add_option("--param", o->param, "beta or alpha")->check(positive_integer());
  cmd->add_option("--p", o->p, "Mean particles per cell")->check(positive_integer());
  cmd->add_option("--steps", o->steps, "Steps of the random walk")->check(CLI::Range(1, 100000));
  cmd->add_option("--jitter", o->jitter,
                  "Step size per coordinate, in cutoffs (0: particles do not move)")
      ->check(non_negative_finite());
  cmd->add_option("--skin", o->skin, "Refit skin, in cutoffs")->check(positive_finite());
  cmd->add_option("-k,--kernel", o->kernel, "count, lj or smooth")
      ->check(CLI::IsMember({"count", "lj", "smooth"}));
  cmd->add_option("-o,--out", o->out, "CSV file to write");
  return [o] { return run_update_bench(*o); };
}

}  // namespace raycut::cli
