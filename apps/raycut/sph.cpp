// raycut sph: the SPH fluid solver of docs/sph.md on any method. Runs a scenario (the HIP RT
// article's drop, or a small one for CI, in the article's model; or the weakly compressible
// validation scenarios hydrostatic and dam-break, docs/sph-validation.md), writes every k-th frame
// as VTK XML PolyData plus a .pvd series (and PNG renders with --png), prints progress on stderr
// and a summary (steps/s, mean milliseconds per pass); --csv appends one row per run;
// --result-csv writes the validation result (pressure profile or surge front). Under mpirun,
// --distributed runs raycut::mpi::SphSolver over the ranks with the same loop (run_steps).
#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <ctime>
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "commands.hpp"
#include "raycut/engine.hpp"
#include "raycut/sph/render.hpp"
#include "raycut/sph/scenario.hpp"
#include "raycut/sph/solver.hpp"
#include "raycut/sph/vtk.hpp"
#include "raycut/tools/files.hpp"
#if defined(RAYCUT_CLI_MPI)
#include <mpi.h>

#include "mpi_session.hpp"
#include "raycut/mpi/sph.hpp"
#endif

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
  // Weakly compressible mode (hydrostatic, dam-break).
  std::string mode;                                       // article or wcsph; empty: the scenario's
  std::string config;                                     // key = value scenario file
  std::vector<std::pair<std::string, std::string>> keys;  // CLI overrides, after the file
  std::string result_csv;
  // Under mpirun: raycut::mpi::SphSolver over the ranks.
  bool distributed = false;
  bool nccl = false;      // --distributed with a GPU method: refreshes and fields by NCCL
  std::vector<int> dims;  // empty: MPI_Dims_create
  bool balance = false;   // cuts at the particle-count quantiles
  int rebalance_every = 1;
};

bool is_validation(const std::string& scenario) {
  return scenario == "hydrostatic" || scenario == "dam-break";
}

// Pressure against depth of a settled column, per particle layer: each fluid particle belongs to
// the lattice layer it started in (bins of dx from the floor at t = 0), so that a layer stays one
// layer however the column compresses (fixed bins would split and merge the compressed layers).
// Time-averaged over the samples added. The reference is exact for any compression: the weight
// per area above a layer is rho0 g (H - y0), with y0 the layer's initial height and H the initial
// column's top (layers * dx), since the mass above a layer never changes.
struct Profile {
  const sph::WcsphConfig& c;
  int layers;
  std::vector<int> layer_of;  // per particle; -1 for boundary particles
  std::vector<double> y0, sy, sp, sr, rmin, rmax;
  std::vector<long> count;
  int samples = 0;
  Profile(const sph::WcsphConfig& config, const std::vector<float>& fixed,
          const std::vector<float>& x0)
      : c(config), layers(static_cast<int>(std::lround(config.height() / config.dx()))) {
    y0.assign(layers, 0.0);
    sy.assign(layers, 0.0);
    sp.assign(layers, 0.0);
    sr.assign(layers, 0.0);
    rmin.assign(layers, 1e30);
    rmax.assign(layers, -1e30);
    count.assign(layers, 0);
    std::vector<long> initial(layers, 0);
    layer_of.assign(fixed.size(), -1);
    for (std::size_t i = 0; i < fixed.size(); ++i) {
      if (fixed[i] != 0.0f) continue;
      const int k =
          std::clamp(static_cast<int>(std::floor(x0[3 * i + 1] / config.dx())), 0, layers - 1);
      layer_of[i] = k;
      y0[k] += x0[3 * i + 1];
      ++initial[k];
    }
    for (int k = 0; k < layers; ++k)
      if (initial[k] > 0) y0[k] /= initial[k];
  }
  void add(const std::vector<float>& x, const std::vector<float>& rho,
           const std::vector<float>& p) {
    for (std::size_t i = 0; i < layer_of.size(); ++i) {
      const int k = layer_of[i];
      if (k < 0) continue;
      sy[k] += x[3 * i + 1];
      sp[k] += p[i];
      sr[k] += rho[i];
      rmin[k] = std::min<double>(rmin[k], rho[i]);
      rmax[k] = std::max<double>(rmax[k], rho[i]);
      ++count[k];
    }
    ++samples;
  }
  void write(io::OutputFile& out, double from, double to) const {
    const double height = layers * c.dx();
    const double rho0 = c.rest_density, g = c.gravity;
    out.write(
        "layer,y,y_now,count,p_mean,rho_mean,rho_min,rho_max,p_hydrostatic,p_rel_error,"
        "rho_rel_dev\n");
    double worst_p = 0, worst_rho = 0, sum_p = 0;
    int counted = 0;
    for (int k = 0; k < layers; ++k) {
      if (count[k] == 0) continue;
      const double y = sy[k] / count[k], pm = sp[k] / count[k], rm = sr[k] / count[k];
      const double ph = rho0 * g * (height - y0[k]);
      const double err = (pm - ph) / ph;
      const double dev = rm / rho0 - 1.0;
      char line[360];
      std::snprintf(line, sizeof line, "%d,%.6f,%.6f,%.2f,%.4f,%.4f,%.4f,%.4f,%.4f,%.6f,%.6f\n", k,
                    y0[k], y, static_cast<double>(count[k]) / samples, pm, rm, rmin[k], rmax[k], ph,
                    err, dev);
      out.write(line);
      if (k < layers - 2) {  // below the top two particle layers
        worst_p = std::max(worst_p, std::abs(err));
        worst_rho = std::max(worst_rho, std::abs(dev));
        sum_p += std::abs(err);
        ++counted;
      }
    }
    std::printf(
        "hydrostatic: H = %.4f m, %d layers, averaged over %d samples in t = [%.3f, %.3f] "
        "s; below the top two layers: |p - rho0 g (H - y0)| / (rho0 g (H - y0)) max %.2f %% "
        "(mean %.2f %%), max |rho_mean / rho0 - 1| = %.3f %% (%d layers)\n",
        height, layers, samples, from, to, 100 * worst_p, counted ? 100 * sum_p / counted : 0.0,
        100 * worst_rho, counted);
    out.commit();
    std::printf("wrote %s\n", out.path().c_str());
  }
};

// The surge front: x_front = the largest fluid particle centre x + dx / 2 (the particle's volume
// edge, so the initial front is exactly x = a), Z = x_front / a, T = t sqrt(2 g / a).
struct FrontSample {
  double t, T, x_front, Z, max_speed, kinetic_energy;
};
FrontSample front_of(double t, const sph::WcsphConfig& c, double mass,
                     const std::vector<float>& fixed, const std::vector<float>& x,
                     const std::vector<float>& v) {
  double xmax = -1e30, vmax2 = 0, ke = 0;
  for (std::size_t i = 0; i < fixed.size(); ++i) {
    if (fixed[i] != 0.0f) continue;
    xmax = std::max<double>(xmax, x[3 * i]);
    const double v2 = double{v[3 * i]} * v[3 * i] + double{v[3 * i + 1]} * v[3 * i + 1] +
                      double{v[3 * i + 2]} * v[3 * i + 2];
    vmax2 = std::max(vmax2, v2);
    ke += 0.5 * mass * v2;
  }
  const double a = c.column_width;
  const double xf = xmax + 0.5 * c.dx();
  return {t, t * std::sqrt(2.0 * c.gravity / a), xf, xf / a, std::sqrt(vmax2), ke};
}

using Clock = std::chrono::steady_clock;

double seconds_since(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// What a run needs beyond the solvers' common calls (size, parameters, method, space, skin, time,
// step, last_times, copy_state): sph::Solver in this process; mpi::SphSolver under --distributed,
// whose step and copy_state are collective, with rank 0 printing and writing. An error rank 0
// meets while writing is thrown on every rank (agree), so none is left in a collective.
struct RunReport {
  std::string where;           // after the method in the first line
  std::string header, values;  // extra CSV columns, each with a leading comma
  std::string summary;         // extra summary lines
};
int rank_of(const sph::Solver&) {
  return 0;
}
void agree(const sph::Solver&, const std::string& error, ErrorCode code) {
  if (!error.empty()) throw Error(code, error);
}
RunReport report(const sph::Solver&, bool, double) {
  return {};
}
double summed_over_ranks(const sph::Solver&, double local) {
  return local;
}

#if defined(RAYCUT_CLI_MPI)
int rank_of(const mpi::SphSolver& solver) {
  return solver.engine().rank();
}
void agree(const mpi::SphSolver&, const std::string& error, ErrorCode code) {
  int failed[2] = {!error.empty(), static_cast<int>(code)};
  MPI_Bcast(failed, 2, MPI_INT, 0, MPI_COMM_WORLD);
  if (failed[0])
    throw Error(static_cast<ErrorCode>(failed[1]),
                error.empty() ? "rank 0 failed to write its outputs" : error);
}
double summed_over_ranks(const mpi::SphSolver&, double local) {
  double sum = 0;
  MPI_Allreduce(&local, &sum, 1, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  return sum;
}
// Collective. `done`: after the steps (the summary, with the steps' CPU ms summed over the
// ranks), else before them (the first line).
RunReport report(const mpi::SphSolver& solver, bool done, double step_cpu_ms) {
  const mpi::SphRunStats s = solver.statistics();
  const std::string dims =
      std::to_string(s.dims[0]) + "x" + std::to_string(s.dims[1]) + "x" + std::to_string(s.dims[2]);
  RunReport r;
  r.where = ", " + std::to_string(s.ranks) + " ranks, domains " + dims;
  if (!done) return r;
  r.header =
      ",ranks,dims,halos_mean,owned_min,owned_max,exchanges,refreshes,migrated,balances,"
      "step_cpu_ms,timer";
  char line[512];
  std::snprintf(
      line, sizeof line, ",%d,%s,%.0f,%llu,%llu,%llu,%llu,%llu,%llu,%.4f,max_over_ranks", s.ranks,
      dims.c_str(), s.halos_mean, static_cast<unsigned long long>(s.owned_min),
      static_cast<unsigned long long>(s.owned_max), static_cast<unsigned long long>(s.exchanges),
      static_cast<unsigned long long>(s.refreshes), static_cast<unsigned long long>(s.migrated),
      static_cast<unsigned long long>(s.balances), step_cpu_ms);
  r.values = line;
  std::snprintf(
      line, sizeof line,
      "distributed: %d ranks (domains %s), pass times the largest over the ranks; "
      "halos %.0f per step (summed over ranks), owned %llu to %llu per rank; %llu "
      "exchanges, %llu refreshes in place; %llu particles migrated; cuts balanced %llu times\n",
      s.ranks, dims.c_str(), s.halos_mean, static_cast<unsigned long long>(s.owned_min),
      static_cast<unsigned long long>(s.owned_max), static_cast<unsigned long long>(s.exchanges),
      static_cast<unsigned long long>(s.refreshes), static_cast<unsigned long long>(s.migrated),
      static_cast<unsigned long long>(s.balances));
  r.summary = line;
  return r;
}
#endif

// Runs `write` on rank 0, then agrees on its outcome: an Error it throws is thrown on every rank.
template <class S, class F>
void on_root(const S& solver, F&& write) {
  std::string error;
  ErrorCode code = ErrorCode::io;
  if (rank_of(solver) == 0) try {
      write();
    } catch (const Error& e) {
      error = e.what();
      code = e.code();
    }
  agree(solver, error, code);
}

// `csv` was opened in append mode before the run (its old rows are already copied).
void append_csv(io::OutputFile& csv, const std::string& scenario, const std::string& method,
                std::size_t n, int frames, double steps_per_s, const sph::StepTimes& mean,
                const RunReport& extra) {
  if (csv.was_empty())
    csv.write("scenario,method,N,frames,steps_per_s,update_ms,density_ms,force_ms,integrate_ms" +
              extra.header + ",gpu,driver,cuda,optix\n");
  const SystemInfo sys = system_info();
  char line[1024];
  std::snprintf(line, sizeof line, "%s,%s,%zu,%d,%.1f,%.4f,%.4f,%.4f,%.4f%s,%s,%s,%s,%s\n",
                scenario.c_str(), method.c_str(), n, frames, steps_per_s, mean.update_ms,
                mean.density_ms, mean.force_ms, mean.integrate_ms, extra.values.c_str(),
                sys.gpu.c_str(), sys.driver.c_str(), sys.cuda.c_str(), sys.optix.c_str());
  csv.write(line);
  csv.commit();
}

template <class S>
int run_steps(const SphOptions& o, const sph::WcsphConfig& config, const sph::SphScenario& scenario,
              int frames, S& solver) {
  const bool wcsph = is_validation(o.scenario);
  const bool root = rank_of(solver) == 0;
  const std::size_t n = solver.size();
  const float rho0 = solver.parameters().rest_density;
  // Output files are opened (temporary files created) before the steps, so that an unwritable
  // path fails now rather than after the run; each appears whole, or not at all, at the end.
  std::optional<io::OutputFile> csv_out, result_out;
  std::optional<sph::VtkSeries> series;
  on_root(solver, [&] {
    if (!o.csv.empty()) csv_out.emplace(o.csv, io::OutputFile::Mode::append);
    if (!o.result_csv.empty()) result_out.emplace(o.result_csv);
    if (!o.out.empty()) series.emplace(o.out, "frames");
  });
  const RunReport where = report(solver, false, 0);
  if (root)
    std::fprintf(stderr,
                 "sph %s: %zu particles, method %s (%s, skin %g m%s), %d frames of dt = %g s\n",
                 scenario.name.c_str(), n, solver.method().c_str(),
                 solver.space() == MemorySpace::device ? "device" : "host", solver.skin(),
                 where.where.c_str(), frames, solver.parameters().dt);
  std::size_t fluid = n;
  if (wcsph && root) {
    const sph::SphParameters& prm = solver.parameters();
    fluid =
        static_cast<std::size_t>(std::count(scenario.fixed.begin(), scenario.fixed.end(), 0.0f));
    const sph::TimeStepLimits lim =
        sph::wcsph_time_step(prm.smoothing_length, prm.sound_speed, 0.1f * prm.sound_speed,
                             100.0f * config.gravity, prm.rest_density, prm.viscosity, config.cfl);
    std::fprintf(stderr,
                 "  wcsph: a = %g m, H = %g m, dx = %g m (%d across a), h = %g m (%g dx), "
                 "%zu fluid + %zu boundary particles (%d layers), m = %g kg\n"
                 "  c0 = %g m/s, B = %g Pa, alpha = %g -> mu = %g Pa s, negative pressure %s; "
                 "dt limits: CFL %g, force %g, viscous %g s; t_end = %g s; damping %g 1/s "
                 "until %g s; gradient correction %g\n",
                 config.column_width, config.height(), config.dx(), config.resolution,
                 prm.smoothing_length, config.h_over_dx, fluid, n - fluid, config.boundary_layers,
                 prm.particle_mass, prm.sound_speed,
                 prm.sound_speed * prm.sound_speed * prm.rest_density / 7.0, config.viscosity_alpha,
                 prm.viscosity, prm.clamp_negative_pressure ? "clamped at 0" : "kept", lim.cfl,
                 lim.force, lim.viscous, config.run_time(), prm.damping, prm.damping_time,
                 prm.gradient_correction);
  }
  // The dam break's front, sampled every 0.05 in T (and at the first and last frames). The
  // samples, the profile and the files are rank 0's; copy_state is every rank's.
  std::vector<FrontSample> fronts;
  std::vector<float> fx, fv, frho, fp;
  const double T_per_t = std::sqrt(2.0 * config.gravity / config.column_width);
  int last_sample = -1;
  double max_mach = 0;
  // The hydrostatic profile: averaged over every 20th step of the last 0.1 s (after the
  // settling damping).
  Profile profile(config, scenario.fixed, scenario.position);
  const double profile_from =
      std::max<double>(solver.parameters().damping_time, config.run_time() - 0.1);
  double profile_first = -1;
  auto sample = [&](bool force) {
    if (!wcsph) return;
    const int bucket = static_cast<int>(std::floor(solver.time() * T_per_t / 0.05 + 1e-9));
    if (!force && bucket == last_sample) return;
    last_sample = bucket;
    solver.copy_state(fx, fv, frho, fp);
    if (!root) return;
    const FrontSample f =
        front_of(solver.time(), config, solver.parameters().particle_mass, scenario.fixed, fx, fv);
    max_mach = std::max(max_mach, f.max_speed / solver.parameters().sound_speed);
    fronts.push_back(f);
  };

  std::vector<float> x, v, rho, p, colour;
  int saved = 0;
  auto save = [&](int frame) {
    if (o.out.empty()) return;
    solver.copy_state(x, v, rho, p);
    on_root(solver, [&] {
      series->write_frame(solver.time(), x.data(), v.data(), rho.data(), p.data(), n);
      if (!o.png) return;
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
    });
    ++saved;
  };

  // Steps are timed alone; output (copies, files, renders) is not.
  sph::StepTimes sum;
  double step_seconds = 0, step_cpu_seconds = 0;
  const auto wall_start = Clock::now();
  auto last_report = wall_start;
  const Progress progress("sph", static_cast<std::uint64_t>(frames), o.quiet);  // each line's ETA
  save(0);
  sample(true);
  for (int frame = 1; frame <= frames; ++frame) {
    const auto start = Clock::now();
    const double cpu_start = cpu_seconds();
    solver.step();
    step_seconds += seconds_since(start);
    step_cpu_seconds += cpu_seconds() - cpu_start;
    sample(frame == frames);
    if (wcsph && config.scenario == "hydrostatic" && solver.time() >= profile_from &&
        (frame % 20 == 0 || frame == frames)) {
      solver.copy_state(fx, fv, frho, fp);
      if (root) profile.add(fx, frho, fp);
      if (profile_first < 0) profile_first = solver.time();
    }
    const sph::StepTimes t = solver.last_times();
    sum.update_ms += t.update_ms;
    sum.density_ms += t.density_ms;
    sum.force_ms += t.force_ms;
    sum.integrate_ms += t.integrate_ms;
    if (frame % o.every == 0 || frame == frames) save(frame);
    if (root && !o.quiet && (seconds_since(last_report) > 1.0 || frame == frames)) {
      last_report = Clock::now();
      const std::string eta = progress.eta(static_cast<std::uint64_t>(frame));
      if (wcsph)
        std::fprintf(stderr, "  frame %d/%d  %.1f steps/s  %s  t = %.4f s  Z = %.3f  KE = %.4g J\n",
                     frame, frames, frame / step_seconds, eta.c_str(), solver.time(),
                     fronts.back().Z, fronts.back().kinetic_energy);
      else
        std::fprintf(stderr, "  frame %d/%d  %.1f steps/s  %s\n", frame, frames,
                     frame / step_seconds, eta.c_str());
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
  const double step_cpu_ms =
      frames > 0 ? 1e3 * summed_over_ranks(solver, step_cpu_seconds) / frames : 0.0;
  const RunReport extra = report(solver, true, step_cpu_ms);
  if (root) {
    std::printf("scenario %s, N = %zu, method %s, %d steps in %.3f s (%.3f s with output)\n",
                scenario.name.c_str(), n, solver.method().c_str(), frames, step_seconds, total_s);
    std::printf("%-12s %10s\n", "", "mean ms");
    std::printf("%-12s %10.4f\n", "update", mean.update_ms);
    std::printf("%-12s %10.4f\n", "density", mean.density_ms);
    std::printf("%-12s %10.4f\n", "force", mean.force_ms);
    std::printf("%-12s %10.4f\n", "integrate", mean.integrate_ms);
    std::printf("%-12s %10.4f\n", "step", frames > 0 ? 1e3 * step_seconds / frames : 0.0);
    std::printf("%-12s %10.4f   (CPU time of the steps, all threads%s)\n", "step CPU", step_cpu_ms,
                extra.summary.empty() ? "" : ", summed over the ranks");
    std::printf("steps/s      %10.1f\n", steps_per_s);
    std::printf("%s", extra.summary.c_str());
    if (series)
      std::printf("wrote %d frames to %s%s\n", saved, series->pvd_path().c_str(),
                  o.png ? " (+ PNG)" : "");
  }
  on_root(solver, [&] {
    if (!csv_out) return;
    append_csv(*csv_out, scenario.name, solver.method(), n, frames, steps_per_s, mean, extra);
    std::printf("wrote %s\n", o.csv.c_str());
  });
  if (!wcsph) return 0;
  solver.copy_state(fx, fv, frho, fp);
  on_root(solver, [&] {
    double ke = 0;
    for (std::size_t i = 0; i < n; ++i)
      if (scenario.fixed[i] == 0.0f)
        ke += 0.5 * solver.parameters().particle_mass *
              (double{fv[3 * i]} * fv[3 * i] + double{fv[3 * i + 1]} * fv[3 * i + 1] +
               double{fv[3 * i + 2]} * fv[3 * i + 2]);
    std::printf("t = %.4f s, fluid kinetic energy %.4g J, max Mach |v|max / c0 = %.3f\n",
                solver.time(), ke, max_mach);
    if (config.scenario == "hydrostatic") {
      if (profile.samples == 0) profile.add(fx, frho, fp);
      if (result_out)
        profile.write(*result_out, profile_first < 0 ? solver.time() : profile_first,
                      solver.time());
      return;
    }
    const FrontSample& f = fronts.back();
    std::printf("dam-break: T = %.3f, Z = %.3f (x_front = %.4f m)\n", f.T, f.Z, f.x_front);
    if (!result_out) return;
    io::OutputFile& out = *result_out;
    out.write("t,T,x_front,Z,max_speed,kinetic_energy\n");
    char line[200];
    for (const FrontSample& s : fronts) {
      std::snprintf(line, sizeof line, "%.6f,%.5f,%.6f,%.5f,%.4f,%.6g\n", s.t, s.T, s.x_front, s.Z,
                    s.max_speed, s.kinetic_energy);
      out.write(line);
    }
    out.commit();
    std::printf("wrote %s (%zu samples)\n", o.result_csv.c_str(), fronts.size());
  });
  return 0;
}

int run_sph(const SphOptions& o) {
  const bool wcsph = is_validation(o.scenario);
  const std::string mode = o.mode.empty() ? (wcsph ? "wcsph" : "article") : o.mode;
  if ((mode == "wcsph") != wcsph)
    throw Error(ErrorCode::invalid_argument,
                "--mode " + mode + " does not go with --scenario " + o.scenario +
                    " (wcsph: hydrostatic or dam-break; article: hiprt-drop or small)");
  if (!wcsph && (!o.config.empty() || !o.keys.empty() || !o.result_csv.empty()))
    throw Error(ErrorCode::invalid_argument,
                "--config, --result-csv and the wcsph options need --scenario hydrostatic or "
                "dam-break");
  sph::WcsphConfig config;
  config.scenario = o.scenario;
  if (!o.config.empty()) {
    config = sph::read_wcsph_config(o.config, config);
    if (config.scenario != o.scenario)
      throw Error(ErrorCode::invalid_argument, o.config + " sets scenario = " + config.scenario +
                                                   ", the command line " + o.scenario);
  }
  for (const auto& [key, value] : o.keys) sph::set_wcsph_key(config, key, value);
  sph::SphScenario scenario = wcsph                        ? sph::wcsph_scenario(config)
                              : o.scenario == "hiprt-drop" ? sph::hiprt_drop()
                                                           : sph::small_drop(o.n);
  const int frames = o.frames >= 0 ? o.frames : scenario.frames;
  if (o.distributed) {
#if defined(RAYCUT_CLI_MPI)
    const MpiSession session;
    std::array<int, 3> dims = {0, 0, 0};
    std::copy(o.dims.begin(), o.dims.end(), dims.begin());
    mpi::select_local_device(MPI_COMM_WORLD);  // one rank per GPU where there are several
    mpi::SphSolver solver(MPI_COMM_WORLD, scenario, o.method, o.skin, dims,
                          o.balance ? mpi::Balance::particles : mpi::Balance::none,
                          o.rebalance_every,
                          o.nccl ? mpi::make_nccl_transport(MPI_COMM_WORLD) : nullptr);
    return run_steps(o, config, scenario, frames, solver);
#else
    throw Error(ErrorCode::unsupported,
                "sph --distributed: this raycut was built without MPI (RAYCUT_MPI)");
#endif
  }
  sph::Solver solver(scenario, o.method, o.skin);
  return run_steps(o, config, scenario, frames, solver);
}

}  // namespace

double cpu_seconds() {
  timespec t{};
  clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t);
  return static_cast<double>(t.tv_sec) + 1e-9 * static_cast<double>(t.tv_nsec);
}

Command add_sph(CLI::App& app) {
  auto* cmd = app.add_subcommand(
      "sph", "SPH fluid (docs/sph.md): the HIP RT article's falling water on any method");
  auto o = std::make_shared<SphOptions>();
  auto* scenario_option =
      cmd->add_option(
             "--scenario", o->scenario,
             "hiprt-drop (131,072 particles) or small (the article's model); hydrostatic or "
             "dam-break (weakly compressible, docs/sph-validation.md)")
          ->check(CLI::IsMember({"hiprt-drop", "small", "hydrostatic", "dam-break"}));
  cmd->add_option("--mode", o->mode,
                  "article or wcsph (default: the scenario's; wcsph alone runs dam-break)")
      ->check(CLI::IsMember({"article", "wcsph"}));
  cmd->add_option("--config", o->config,
                  "Scenario file of key = value lines (docs/sph-validation.md); the options below "
                  "override it");
  const auto key = [cmd, o](const char* flag, const char* name, const char* help) {
    cmd->add_option_function<std::string>(
        flag, [o, name](const std::string& value) { o->keys.emplace_back(name, value); }, help);
  };
  key("--c0", "c0",
      "wcsph: speed of sound in m/s (default 10 sqrt(2 g H), dam-break 20 sqrt(g H))");
  key("--dx", "dx", "wcsph: particle spacing in m (sets --resolution = a / dx)");
  key("--resolution", "resolution", "wcsph: particles across the column width a (default 10)");
  key("--cfl", "cfl", "wcsph: time-step coefficient (default 0.25)");
  key("--viscosity-alpha", "viscosity_alpha",
      "wcsph: Monaghan's alpha, mu = rho0 alpha h c0 / 20 (default 0.04)");
  key("--h-over-dx", "h_over_dx", "wcsph: support radius h / dx (default 2)");
  key("--layers", "boundary_layers", "wcsph: layers of fixed boundary particles (default 3)");
  key("--negative-pressure", "negative_pressure", "wcsph: clamp (default) or keep");
  key("--column-width", "column_width", "wcsph: a in m (default 0.1)");
  key("--column-height", "column_height", "wcsph: H in m (default 2 a)");
  key("--tank-length", "tank_length", "wcsph: the tank's length in m (default 5 a / a)");
  key("--end-time", "end_time", "wcsph: simulated seconds (default T = 3.3 / 0.5 s)");
  key("--damping", "damping",
      "wcsph: settling damping rate in 1/s, >= 0 (default c0 / H, hydrostatic; 0: none)");
  key("--damping-time", "damping_time",
      "wcsph: damp while t < this, >= 0 s (default 0.3 s, hydrostatic)");
  cmd->add_option("--result-csv", o->result_csv,
                  "wcsph: write the pressure profile (hydrostatic) or the surge front (dam-break)");
  cmd->add_option("-n,--n", o->n, "Particles of the small scenario")->check(positive_integer());
  cmd->add_option("-m,--method", o->method, "Interaction method, or auto");
  cmd->add_option("--frames", o->frames, "Steps to run (default: the scenario's, 200; 0 runs none)")
      ->check(count_option());
  cmd->add_option("--every", o->every, "Save every k-th frame (with --out)")
      ->check(positive_integer());
  cmd->add_option("-o,--out", o->out, "Folder for frames.pvd, the .vtp frames and PNGs");
  cmd->add_flag("--png", o->png, "Also render saved frames to PNG (needs --out)");
  cmd->add_option("--colour", o->colour, "PNG colouring: density or speed")
      ->check(CLI::IsMember({"density", "speed"}));
  cmd->add_option("--skin", o->skin,
                  "Refit skin in m for the OptiX methods (default h; 0 rebuilds every step); with "
                  "--distributed the halo skin (default h / 2; 0 exchanges every step)")
      ->check(non_negative_finite());
  auto* distributed = cmd->add_flag(
      "--distributed", o->distributed,
      "Under mpirun: the solver over the ranks (raycut::mpi::SphSolver; a GPU method keeps the "
      "step on the GPU), domains over the particles' extent; rank 0 writes the outputs, pass "
      "times the largest over ranks");
  cmd->add_option("--dims", o->dims, "--distributed: domains per axis, 0 = MPI chooses")
      ->delimiter(',')
      ->expected(3)
      ->needs(distributed);
  cmd->add_flag("--nccl", o->nccl,
                "--distributed with a GPU method: halo refreshes and fields GPU to GPU by NCCL "
                "(one rank per GPU)")
      ->needs(distributed);
  auto* balance =
      cmd->add_flag("--balance", o->balance,
                    "--distributed: cuts at the particle-count quantiles of each split axis "
                    "(DistributedOptions::balance) at build and every --rebalance-every "
                    "exchanges, instead of equal slabs of the extent at build")
          ->needs(distributed);
  cmd->add_option("--rebalance-every", o->rebalance_every,
                  "--balance: move the cuts again every N exchanges (default 1; 0: at build only)")
      ->check(CLI::NonNegativeNumber)
      ->needs(balance);
  cmd->add_option("--csv", o->csv, "Append a result row to this CSV file");
  cmd->add_flag("-q,--quiet", o->quiet, "No progress lines");
  return [o, scenario_option] {
    if (o->png && o->out.empty()) throw Error(ErrorCode::invalid_argument, "--png needs --out DIR");
    // --mode wcsph alone runs the dam break.
    if (o->mode == "wcsph" && scenario_option->count() == 0) o->scenario = "dam-break";
    return run_sph(*o);
  };
}

}  // namespace raycut::cli
