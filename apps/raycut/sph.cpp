// raycut sph: the SPH fluid solver of spec/SPH.md on any method. Runs a scenario (the HIP RT
// article's drop, or a small one for CI), writes every k-th frame as VTK XML PolyData plus a .pvd
// series (and PNG renders with --png), prints progress on stderr and a summary (steps/s, mean
// milliseconds per pass); --csv appends one row per run.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "commands.hpp"
#include "raycut/engine.hpp"
#include "sph/render.hpp"
#include "sph/scenario.hpp"
#include "sph/solver.hpp"
#include "sph/vtk.hpp"

namespace raycut::cli {
namespace {

struct SphOptions {
  std::string scenario = "hiprt-drop";
  std::size_t n = 4000;
  std::string method = "auto";
  int frames = -1;  // the scenario's
  int every = 1;
  std::string out;
  bool png = false;
  std::string colour = "density";
  float skin = -1;
  std::string csv;
  bool quiet = false;
};

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

void append_csv(const std::string& path, const std::string& scenario, const sph::Solver& solver,
                int frames, double steps_per_s, const sph::StepTimes& mean) {
  const bool fresh = !std::filesystem::exists(path) || std::filesystem::file_size(path) == 0;
  std::ofstream csv(path, std::ios::app);
  if (!csv) throw Error(ErrorCode::io, path + ": cannot open for writing");
  if (fresh)
    csv << "scenario,method,N,frames,steps_per_s,update_ms,density_ms,force_ms,integrate_ms,gpu,"
           "driver,cuda,optix\n";
  const SystemInfo sys = system_info();
  char line[512];
  std::snprintf(line, sizeof line, "%s,%s,%zu,%d,%.1f,%.4f,%.4f,%.4f,%.4f,%s,%s,%s,%s\n",
                scenario.c_str(), solver.method().c_str(), solver.size(), frames, steps_per_s,
                mean.update_ms, mean.density_ms, mean.force_ms, mean.integrate_ms, sys.gpu.c_str(),
                sys.driver.c_str(), sys.cuda.c_str(), sys.optix.c_str());
  csv << line;
  if (!csv) throw Error(ErrorCode::io, path + ": write failed");
}

int run_sph(const SphOptions& o) {
  sph::SphScenario scenario = o.scenario == "hiprt-drop" ? sph::hiprt_drop() : sph::small_drop(o.n);
  const int frames = o.frames >= 0 ? o.frames : scenario.frames;
  sph::Solver solver(scenario, o.method, o.skin);
  const std::size_t n = solver.size();
  const float rho0 = solver.parameters().rest_density;
  std::fprintf(stderr, "sph %s: %zu particles, method %s (%s, skin %g m), %d frames of dt = %g s\n",
               scenario.name.c_str(), n, solver.method().c_str(),
               solver.space() == MemorySpace::device ? "device" : "host", solver.skin(), frames,
               solver.parameters().dt);

  std::optional<sph::VtkSeries> series;
  if (!o.out.empty()) series.emplace(o.out, "frames");
  std::vector<float> x, v, rho, p, colour;
  int saved = 0;
  auto save = [&](int frame) {
    if (o.out.empty()) return;
    solver.copy_state(x, v, rho, p);
    series->write_frame(solver.time(), x.data(), v.data(), rho.data(), p.data(), n);
    if (o.png) {
      float lo = 0.0f, hi = 2.0f * rho0;  // fixed ranges: one colour scale per sequence
      if (o.colour == "speed") {
        colour.resize(n);
        for (std::size_t i = 0; i < n; ++i)
          colour[i] = std::sqrt(v[3 * i] * v[3 * i] + v[3 * i + 1] * v[3 * i + 1] +
                                v[3 * i + 2] * v[3 * i + 2]);
        lo = 0.0f;
        hi = 4.0f;
      }
      char name[64];
      std::snprintf(name, sizeof name, "frame_%06d.png", frame);
      sph::render_png((std::filesystem::path(o.out) / name).string(), x.data(),
                      o.colour == "speed" ? colour.data() : rho.data(), n, lo, hi);
    }
    ++saved;
  };

  // Steps are timed alone; output (copies, files, renders) is not.
  sph::StepTimes sum;
  double step_seconds = 0;
  const auto wall_start = Clock::now();
  auto last_report = wall_start;
  save(0);
  for (int frame = 1; frame <= frames; ++frame) {
    const auto start = Clock::now();
    solver.step();
    step_seconds += seconds_since(start);
    const sph::StepTimes t = solver.last_times();
    sum.update_ms += t.update_ms;
    sum.density_ms += t.density_ms;
    sum.force_ms += t.force_ms;
    sum.integrate_ms += t.integrate_ms;
    if (frame % o.every == 0 || frame == frames) save(frame);
    if (!o.quiet && (seconds_since(last_report) > 1.0 || frame == frames)) {
      last_report = Clock::now();
      std::fprintf(stderr, "  frame %d/%d  %.1f steps/s\n", frame, frames, frame / step_seconds);
    }
  }
  const double total_s = seconds_since(wall_start);

  const double steps_per_s = frames > 0 ? frames / step_seconds : 0.0;
  sph::StepTimes mean;
  if (frames > 0) {
    mean.update_ms = sum.update_ms / frames;
    mean.density_ms = sum.density_ms / frames;
    mean.force_ms = sum.force_ms / frames;
    mean.integrate_ms = sum.integrate_ms / frames;
  }
  std::printf("scenario %s, N = %zu, method %s, %d steps in %.3f s (%.3f s with output)\n",
              scenario.name.c_str(), n, solver.method().c_str(), frames, step_seconds, total_s);
  std::printf("%-12s %10s\n", "", "mean ms");
  std::printf("%-12s %10.4f\n", "update", mean.update_ms);
  std::printf("%-12s %10.4f\n", "density", mean.density_ms);
  std::printf("%-12s %10.4f\n", "force", mean.force_ms);
  std::printf("%-12s %10.4f\n", "integrate", mean.integrate_ms);
  std::printf("%-12s %10.4f\n", "step", frames > 0 ? 1e3 * step_seconds / frames : 0.0);
  std::printf("steps/s      %10.1f\n", steps_per_s);
  if (series)
    std::printf("wrote %d frames to %s%s\n", saved, series->pvd_path().c_str(),
                o.png ? " (+ PNG)" : "");
  if (!o.csv.empty()) append_csv(o.csv, scenario.name, solver, frames, steps_per_s, mean);
  return 0;
}

}  // namespace

Command add_sph(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "sph", "SPH fluid (spec/SPH.md): the HIP RT article's falling water on any method");
  auto o = std::make_shared<SphOptions>();
  cmd->add_option("--scenario", o->scenario, "hiprt-drop (131,072 particles) or small")
      ->check(CLI::IsMember({"hiprt-drop", "small"}));
  cmd->add_option("-n,--n", o->n, "Particles of the small scenario")->check(CLI::PositiveNumber);
  cmd->add_option("-m,--method", o->method, "Interaction method, or auto");
  cmd->add_option("--frames", o->frames, "Steps to run (default: the scenario's, 200)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--every", o->every, "Save every k-th frame (with --out)")
      ->check(CLI::PositiveNumber);
  cmd->add_option("-o,--out", o->out, "Folder for frames.pvd, the .vtp frames and PNGs");
  cmd->add_flag("--png", o->png, "Also render saved frames to PNG (needs --out)");
  cmd->add_option("--colour", o->colour, "PNG colouring: density or speed")
      ->check(CLI::IsMember({"density", "speed"}));
  cmd->add_option("--skin", o->skin,
                  "Refit skin in m for the OptiX methods (default h; 0 rebuilds every step)")
      ->check(CLI::NonNegativeNumber);
  cmd->add_option("--csv", o->csv, "Append a result row to this CSV file");
  cmd->add_flag("-q,--quiet", o->quiet, "No progress lines");
  return [o] {
    if (o->png && o->out.empty()) throw Error(ErrorCode::invalid_argument, "--png needs --out DIR");
    return run_sph(*o);
  };
}

}  // namespace raycut::cli
