// The subcommands of the raycut tool. Each registers its options on a CLI11 subcommand and
// returns the process exit code when run: 0 success, 1 a check failed, 2 bad usage or input.
#pragma once

#include <CLI/CLI.hpp>

#include <chrono>
#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "raycut/box.hpp"
#include "raycut/engine.hpp"
#include "raycut/tools/generators.hpp"
#include "raycut/tools/system_info.hpp"

namespace raycut::cli {

using Command = std::function<int()>;

Command add_check(CLI::App& app);
Command add_bench(CLI::App& app);
Command add_update_bench(CLI::App& app);
Command add_sph(CLI::App& app);
Command add_neighbours(CLI::App& app);

// Expands "all" / "default" and checks the names; throws raycut::Error for unknown ones.
std::vector<std::string> resolve_methods(const std::vector<std::string>& names);

// A configuration of the "uniform" or "surface" suite, refused (Error) when p * param^3 does not
// fit in 64 bits or its particles do not fit in host memory (bytes_per_particle: the
// subcommand's estimate of what it holds per particle).
PointCloud suite_cloud(const std::string& suite, int param, int p, std::uint64_t seed,
                       double bytes_per_particle);
// p * param^3, the suite's particle count, in checked 64-bit arithmetic: Error(invalid_argument)
// when it overflows.
std::uint64_t suite_particles(int param, int p);
// Refuses (Error(out_of_memory)) `n` particles at `bytes_per_particle` each when that is more than
// the available host memory; `what` names the run ("check: family uniform").
void require_particles_fit(std::uint64_t n, double bytes_per_particle, const std::string& what);

// Option checks whose messages say what is wanted and quote what was given (CLI11's ranges
// print 310 digits): "--cutoff: must be a finite number > 0, got '0.1abc'".
CLI::Validator positive_finite();      // a float, finite and > 0
CLI::Validator non_negative_finite();  // a float, finite and >= 0
CLI::Validator positive_integer();     // 1 .. 2^31 - 1
CLI::Validator count_option();         // a whole number >= 0 (no sign, no exponent)
CLI::Validator cutoff_option();        // a double in [2^-60, 2^60], checked before float
CLI::Validator seed_option();          // a whole number in [0, 2^64 - 1]: -1 does not wrap
CLI::Validator one_of(std::vector<std::string> names, std::string what);

// --cell and --pbc as given: tokens, each holding one or more values (separated by spaces or
// commas), so both `--cell 4 4 4` and `--cell "4 0 0 0 4 0 0 0 4"` work.
struct BoxOptions {
  std::vector<std::string> cell, pbc;
  bool given() const { return !cell.empty() || !pbc.empty(); }
};
// Registers --cell and --pbc on a subcommand.
void add_box_options(CLI::App& cmd, BoxOptions& o);
// The box of the options, over `base` (an input file's box, or open): --cell replaces the cell
// (pbc all true unless --pbc says otherwise), --pbc alone the periodic axes of base's cell.
// Error(invalid_argument) naming the option: a malformed value, --pbc with no cell, or a box
// that validate() refuses (its message).
Box resolve_box(const BoxOptions& o, const Box& base = Box::open());
// "4x4x4 (pbc T T F)" or "[[ax ay az] [bx by bz] [cx cy cz]] (pbc T T T)", for messages and rows.
std::string describe_box(const Box& box);

// A progress line on stderr for long runs: "what: 40% (4/10), 12 s, ETA 18 s". Nothing before
// 3 s have passed (short runs stay silent), then at most twice a second, on one line rewritten
// with '\r' on a terminal and a line every 10 s otherwise (logs); nothing at all when quiet.
// RAYCUT_PROGRESS_SECONDS=T sets both the wait and the interval to T seconds (0: a line at every
// step).
class Progress {
 public:
  Progress(std::string what, std::uint64_t total, bool quiet);
  void update(std::uint64_t done);
  // Ends the line, if one was printed.
  void done();
  // "ETA 18 s" after `done` of `total` steps, from the time elapsed since construction.
  std::string eta(std::uint64_t done) const;

 private:
  double elapsed() const;
  std::string what_;
  std::uint64_t total_;
  bool quiet_, terminal_, printed_ = false;
  double first_ = 3.0, interval_;  // seconds before the first line, and between lines
  double last_ = -1e30;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
};

// CPU seconds of this process, all its threads (CLOCK_PROCESS_CPUTIME_ID): the work, whatever the
// cores are shared with.
double cpu_seconds();

// The median of samples (mean of the middle two for an even count).
double median(std::vector<double> samples);

// The CSV columns every benchmark row ends with: what it ran on (gpu,driver,cuda,optix).
std::string environment_columns(const SystemInfo& sys, bool with_optix);

// raycut bench --distributed (distributed_bench.cpp, built with raycut::mpi).
struct DistributedBenchOptions {
  bool enabled = false;
  std::vector<std::uint64_t> n_per_rank, n_total;  // weak or strong scaling
  float skin = 0.3f;
  std::vector<int> dims;     // empty: MPI_Dims_create
  bool all_rows = false;     // DistributedOptions::owned_rows_only = false
  bool balance = false;      // DistributedOptions::balance = particles
  bool halo_images = false;  // DistributedOptions::local_images = false
  bool device = false;       // positions (and the step) in device memory: the device-resident path
  bool nccl = false;         // halo refreshes by make_nccl_transport (with device)
  int steps = 1;             // refresh steps timed after each exchange
};
void add_distributed_bench_options(CLI::App& bench, DistributedBenchOptions& o);
int run_distributed_bench(const DistributedBenchOptions& o, const std::vector<std::string>& methods,
                          int reps, std::uint64_t seed, const std::string& out);

}  // namespace raycut::cli
