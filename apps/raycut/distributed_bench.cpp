// raycut bench --distributed, under mpirun: the LJ liquid (density 0.8442, rc 2.5, uniform random
// in a periodic cube) through raycut::mpi::DistributedEngine. Per repetition and phase the time
// is MPI_Wtime's, the largest over the ranks (the slowest rank sets the step); one warm-up, then
// medians, one CSV row per (method, size) written by rank 0. A repetition is a full exchange
// (migration, new halos, local builds; timed apart) and then --steps steps, each a halo refresh
// (the skin keeps the halo set) plus the fused lj_forces pass. Weak scaling: --n-per-rank particles
// on every rank; strong: --n in total. --device: positions in device memory (the device-resident
// path: the step's positions come from the device, lj_forces stays there), and at one rank the
// plain Engine's build + lj_forces over the same positions, timed in the same run, the
// reference the distributed step is set against.
#include <mpi.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <memory>
#include <numeric>
#include <optional>
#include <string>
#include <vector>

#include "commands.hpp"
#include "mpi_session.hpp"
#include "raycut/engine.hpp"
#include "raycut/mpi/distributed.hpp"
#include "raycut/tools/device_array.hpp"
#include "raycut/tools/files.hpp"

namespace raycut::cli {
namespace {

constexpr double lj_density = 0.8442;
constexpr float lj_cutoff = 2.5f;

// splitmix64: coordinate k of the liquid from (seed, k) alone, so that N particles are the same
// system whatever the number of ranks (strong scaling compares like with like).
std::uint64_t mix(std::uint64_t x) {
  x += 0x9e3779b97f4a7c15ULL;
  x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ULL;
  x = (x ^ (x >> 27)) * 0x94d049bb133111ebULL;
  return x ^ (x >> 31);
}

// This rank's share of the liquid: n / size particles (the first n % size ranks one more), ids
// contiguous by rank, uniform in [0, side)^3.
struct Share {
  std::vector<float> xyz;
  std::vector<std::uint64_t> ids;
};
Share liquid_share(std::uint64_t n, double side, int rank, int size, std::uint64_t seed) {
  const std::uint64_t base = n / size, extra = n % size;
  const std::uint64_t mine = base + (static_cast<std::uint64_t>(rank) < extra);
  const std::uint64_t first = rank * base + std::min<std::uint64_t>(rank, extra);
  Share s;
  s.xyz.resize(3 * mine);
  s.ids.resize(mine);
  std::iota(s.ids.begin(), s.ids.end(), first);
  const std::uint64_t stream = mix(seed);
  for (std::size_t k = 0; k < s.xyz.size(); ++k) {
    const double u = static_cast<double>(mix(stream ^ (3 * first + k)) >> 11) * 0x1p-53;
    float& x = s.xyz[k];
    x = static_cast<float>(u * side);
    if (static_cast<double>(x) >= side) x = std::nextafter(x, 0.0f);  // stay in [0, side)
  }
  return s;
}

// Per repetition: full exchange, refresh, compute (lj_forces after the refresh), step = refresh
// + compute, each the largest over the ranks; then the CPU time of the compute and the step,
// summed over the ranks: the work, whatever the ranks share cores with (the step's includes
// what MPI spends polling while it waits).
enum Phase {
  exchange_phase,
  refresh_phase,
  compute_phase,
  step_phase,
  wall_phases,
  compute_cpu = wall_phases,
  step_cpu,
  phases
};

struct Run {
  std::vector<double> samples[phases];
  std::vector<double> plain, plain_build;  // one rank, --device: the plain Engine's build +
                                           // lj_forces, and its build alone
  // Within the refresh (engine.stats(), this rank's): update()'s own pass, the halo refresh,
  // the local engine's build.
  std::vector<double> update, halo_refresh, local_build;
  double build_ms = 0;
  std::uint64_t pairs = 0, halos = 0, owned_min = 0, owned_max = 0;
  bool owned_rows_only = false;
  std::array<int, 3> dims{};
};

Run run_method(MPI_Comm comm, const DistributedBenchOptions& o, const std::string& method,
               std::uint64_t n, double side, int reps, std::uint64_t seed) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  mpi::DistributedOptions options;
  options.method = method;
  options.skin = o.skin;
  options.owned_rows_only = !o.all_rows;
  if (o.balance) options.balance = mpi::Balance::particles;
  options.local_images = !o.halo_images;
  if (o.nccl) options.transport = mpi::make_nccl_transport(comm);
  for (std::size_t a = 0; a < o.dims.size(); ++a) options.dims[a] = o.dims[a];
  mpi::DistributedEngine engine(comm, options);
  const Share share = liquid_share(n, side, rank, size, seed);
  const Box box = Box::orthorhombic(side, side, side);
  std::optional<DeviceArray> on_device;
  PositionsView given{share.xyz.data(), share.ids.size(), MemorySpace::host};
  if (o.device) {
    on_device.emplace(share.xyz);
    given = {on_device->data(), share.ids.size(), MemorySpace::device};
  }

  Run run;
  MPI_Barrier(comm);
  double start = MPI_Wtime();
  engine.build(given, share.ids.data(), lj_cutoff, box);
  double local = 1e3 * (MPI_Wtime() - start);
  MPI_Allreduce(&local, &run.build_ms, 1, MPI_DOUBLE, MPI_MAX, comm);

  // Warm-up, and what the rows report: pairs (each counted from both ends), halos, balance.
  const Results counts = engine.compute(Kernel::count);
  std::uint64_t mine[4] = {0, engine.halos(), engine.owned(), engine.owned()};
  for (std::uint32_t c : counts.count) mine[0] += c;
  std::uint64_t sums[2], owned_min = 0, owned_max = 0;
  MPI_Allreduce(mine, sums, 2, MPI_UINT64_T, MPI_SUM, comm);
  MPI_Allreduce(&mine[2], &owned_min, 1, MPI_UINT64_T, MPI_MIN, comm);
  MPI_Allreduce(&mine[3], &owned_max, 1, MPI_UINT64_T, MPI_MAX, comm);
  run.pairs = sums[0] / 2;
  run.halos = sums[1];
  run.owned_min = owned_min;
  run.owned_max = owned_max;
  run.owned_rows_only = engine.owned_rows_only();
  run.dims = engine.decomposition().dims;
  engine.compute(Kernel::lj_forces);

  // The largest over the ranks of the wall phases, the sum of the CPU ones, into the samples.
  const auto record = [&](double* t, int first, int last) {
    double reduced[phases];
    MPI_Allreduce(t + first, reduced + first, std::min(last, int{wall_phases}) - first, MPI_DOUBLE,
                  MPI_MAX, comm);
    if (last > wall_phases)
      MPI_Allreduce(t + wall_phases, reduced + wall_phases, last - wall_phases, MPI_DOUBLE, MPI_SUM,
                    comm);
    for (int p = first; p < last; ++p) run.samples[p].push_back(1e3 * reduced[p]);
  };
  for (int r = 0; r < reps; ++r) {
    double t[phases];
    MPI_Barrier(comm);
    start = MPI_Wtime();
    engine.exchange();
    t[exchange_phase] = MPI_Wtime() - start;
    record(t, exchange_phase, exchange_phase + 1);
    // Untimed: the integrator's output, where the positions live.
    const std::vector<float> xyz = engine.positions();
    if (o.device) on_device.emplace(xyz);
    for (int step = 0; step < o.steps; ++step) {  // refreshes, as between an MD run's exchanges
      MPI_Barrier(comm);
      start = MPI_Wtime();
      const double cpu_start = cpu_seconds();
      if (engine.update(o.device ? on_device->data() : xyz.data()))  // nothing moved: in the skin
        throw Error(ErrorCode::internal, "bench --distributed: update() exchanged, not refreshed");
      const double refreshed = MPI_Wtime(), cpu_refreshed = cpu_seconds();
      run.update.push_back(engine.stats().update_ms);
      run.halo_refresh.push_back(engine.stats().exchange_ms);
      run.local_build.push_back(engine.stats().build_ms);
      if (o.device)
        engine.run(Kernel::lj_forces);  // results stay on the device
      else
        engine.compute(Kernel::lj_forces);
      const double computed = MPI_Wtime(), cpu_computed = cpu_seconds();
      t[refresh_phase] = refreshed - start;
      t[compute_phase] = computed - refreshed;
      t[step_phase] = computed - start;
      t[compute_cpu] = cpu_computed - cpu_refreshed;
      t[step_cpu] = cpu_computed - cpu_start;
      record(t, refresh_phase, phases);
    }
  }
  if (o.device && size == 1) {  // the reference: the plain engine, same positions, same GPU
    Engine plain(method);
    for (int r = 0; r <= reps; ++r) {  // the first is the warm-up
      // Untimed, as before the distributed steps: the integrator's output on the device.
      const DeviceArray xyz(engine.positions());
      for (int step = 0; step < o.steps; ++step) {
        start = MPI_Wtime();
        plain.build(xyz.view(), lj_cutoff, box);
        const double built = MPI_Wtime();
        plain.run(Kernel::lj_forces);
        if (r > 0) run.plain.push_back(1e3 * (MPI_Wtime() - start));
        if (r > 0) run.plain_build.push_back(1e3 * (built - start));
      }
    }
  }
  return run;
}

}  // namespace

void add_distributed_bench_options(CLI::App& bench, DistributedBenchOptions& o) {
  auto* flag = bench.add_flag(
      "--distributed", o.enabled,
      "Under mpirun: the periodic LJ liquid (density 0.8442, rc 2.5) through the distributed "
      "engine, a step = halo refresh + lj_forces (uses -m, -r, -o, --seed; the suite options "
      "do not apply)");
  auto* weak = bench
                   .add_option("--n-per-rank", o.n_per_rank,
                               "--distributed, weak scaling: particles per rank (list)")
                   ->delimiter(',')
                   ->check(count_option())
                   ->needs(flag);
  bench.add_option("--n", o.n_total, "--distributed, strong scaling: particles in total (list)")
      ->delimiter(',')
      ->check(count_option())
      ->needs(flag)
      ->excludes(weak);
  bench.add_option("--skin", o.skin, "--distributed: halo skin (> 0; halos reach rc + skin)")
      ->check(positive_finite())
      ->needs(flag);
  bench.add_option("--dims", o.dims, "--distributed: domains per axis, 0 = MPI chooses")
      ->delimiter(',')
      ->expected(3)
      ->needs(flag);
  bench
      .add_flag("--all-rows", o.all_rows,
                "--distributed: one local engine over owned + halos, halo rows discarded (the "
                "scheme of methods without query points), instead of owned rows only")
      ->needs(flag);
  bench
      .add_flag("--balance", o.balance,
                "--distributed: cuts at the particle-count quantiles of each split axis at build "
                "(DistributedOptions::balance), instead of equal slabs")
      ->needs(flag);
  bench
      .add_flag("--halo-images", o.halo_images,
                "--distributed: every periodic axis imaged by halos, single-domain ones too "
                "(DistributedOptions::local_images = false): at one rank, the exchanges and "
                "refreshes of several ranks, sent to itself")
      ->needs(flag);
  auto* device =
      bench
          .add_flag("--device", o.device,
                    "--distributed: positions in device memory, the step on the GPU (the "
                    "device-resident path; GPU methods); at one rank also the plain engine's "
                    "build + lj_forces (plain_step_ms)")
          ->needs(flag);
  bench
      .add_flag("--nccl", o.nccl,
                "--distributed --device: halo refreshes GPU to GPU by NCCL (one rank per GPU)")
      ->needs(device);
  bench
      .add_option("--steps", o.steps,
                  "--distributed: refresh steps timed after each exchange (default 1: the step "
                  "right after an exchange; more: the steps between exchanges of an MD run)")
      ->check(CLI::Range(1, 1000))
      ->needs(flag);
}

int run_distributed_bench(const DistributedBenchOptions& o, const std::vector<std::string>& names,
                          int reps, std::uint64_t seed, const std::string& out) {
  if (o.n_per_rank.empty() == o.n_total.empty())
    throw Error(ErrorCode::invalid_argument,
                "bench --distributed: give --n-per-rank (weak scaling) or --n (strong scaling)");
  const MpiSession session;
  MPI_Comm comm = MPI_COMM_WORLD;
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  if (o.device && mpi::select_local_device(comm) < 0)
    throw Error(ErrorCode::unsupported, "bench --distributed --device: no CUDA device");
  const auto methods = resolve_methods(names);
  const bool weak = !o.n_per_rank.empty();
  std::vector<std::uint64_t> sizes;
  for (std::uint64_t n : weak ? o.n_per_rank : o.n_total) {
    // The same on every rank: a refusal here stops them all alike.
    if (n == 0 || n > (std::uint64_t{1} << 48) / static_cast<std::uint64_t>(size))
      throw Error(ErrorCode::invalid_argument,
                  std::string("bench --distributed: ") + (weak ? "--n-per-rank " : "--n ") +
                      std::to_string(n) + " particles: give 1 to 2^48 in total");
    sizes.push_back(weak ? n * size : n);
  }

  // Rank 0 writes; an output it cannot open stops every rank before any work.
  std::unique_ptr<io::OutputFile> csv;
  std::string open_error;
  if (rank == 0) try {
      csv = std::make_unique<io::OutputFile>(out);
    } catch (const Error& e) {
      open_error = e.what();
    }
  int failed = !open_error.empty();
  MPI_Bcast(&failed, 1, MPI_INT, 0, comm);
  if (failed) throw Error(ErrorCode::io, rank == 0 ? open_error : "rank 0 cannot write " + out);

  const SystemInfo sys = system_info();
  const std::string environment = environment_columns(sys, true);
  if (rank == 0) {
    csv->write(
        "suite,method,rows,ranks,dims,balance,images,scaling,N,N_per_rank,cutoff,skin,pairs,halos,"
        "owned_"
        "min,"
        "owned_max,build_ms,exchange_ms,refresh_ms,compute_ms,step_ms,step_ms_min,step_ms_max,"
        "compute_cpu_ms,step_cpu_ms,update_ms,halo_refresh_ms,local_build_ms,positions,transport,"
        "plain_step_ms,reps,steps,timer,gpu,driver,cuda,optix\n");
    std::fprintf(stderr, "raycut bench --distributed: %d ranks, %s scaling, %d reps, on %s -> %s\n",
                 size, weak ? "weak" : "strong", reps,
                 environment.substr(0, environment.find(',')).c_str(), out.c_str());
  }
  int status = 0;
  for (std::uint64_t n : sizes) {
    const double side = std::cbrt(static_cast<double>(n) / lj_density);
    // In a periodic box no wider than 2 rc each pair is one image: E[pairs] = N (N - 1) / 2 times
    // the sphere's share of the box, the same for every target, so the count is exact to ~1 /
    // sqrt(pairs). Missing or duplicated halos move it by far more than 2 %.
    const double sphere = 4.0 / 3.0 * M_PI * std::pow(static_cast<double>(lj_cutoff), 3);
    const double expected =
        0.5 * static_cast<double>(n) * (n - 1.0) * sphere / (side * side * side);
    for (const auto& method : methods) {
      const Run run = run_method(comm, o, method, n, side, reps, seed);
      const auto& s = run.samples;
      const bool pairs_ok = side < 2 * lj_cutoff ||
                            std::abs(static_cast<double>(run.pairs) - expected) <= 0.02 * expected;
      if (!pairs_ok) status = 1;
      // Rank 0 writes the row; a write that fails (a full disk) stops every rank here, not only
      // rank 0 (the others would wait in the next run's collectives).
      const auto write_row = [&] {
        char plain_text[32] = "";  // empty: not measured (more than one rank, or host positions)
        if (!run.plain.empty())
          std::snprintf(plain_text, sizeof plain_text, "%.4f", median(run.plain));
        const std::string plain = plain_text;
        char row[1024];
        std::snprintf(
            row, sizeof row,
            "lj-liquid-pbc,%s,%s,%d,%dx%dx%d,%s,%s,%s,%llu,%llu,%g,%g,%llu,%llu,%llu,%llu,%.4f,%."
            "4f,"
            "%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%.4f,%s,%s,%s,%d,%d,mpi_wtime_max,%s\n",
            method.c_str(), run.owned_rows_only ? "owned" : "all", size, run.dims[0], run.dims[1],
            run.dims[2], o.balance ? "particles" : "none", o.halo_images ? "halos" : "local",
            weak ? "weak" : "strong", static_cast<unsigned long long>(n),
            static_cast<unsigned long long>(n / size), lj_cutoff, o.skin,
            static_cast<unsigned long long>(run.pairs), static_cast<unsigned long long>(run.halos),
            static_cast<unsigned long long>(run.owned_min),
            static_cast<unsigned long long>(run.owned_max), run.build_ms, median(s[exchange_phase]),
            median(s[refresh_phase]), median(s[compute_phase]), median(s[step_phase]),
            *std::min_element(s[step_phase].begin(), s[step_phase].end()),
            *std::max_element(s[step_phase].begin(), s[step_phase].end()), median(s[compute_cpu]),
            median(s[step_cpu]), median(run.update), median(run.halo_refresh),
            median(run.local_build), o.device ? "device" : "host", o.nccl ? "nccl" : "mpi-host",
            plain.c_str(), reps, o.steps, environment.c_str());
        csv->write(row);
        csv->flush();
        std::fprintf(
            stderr,
            "  N=%llu %s (%s rows): step %.3f ms = refresh %.3f + lj_forces %.3f; exchange "
            "%.3f ms; CPU over ranks: step %.3f ms, lj_forces %.3f ms; %llu pairs, %llu "
            "halos\n",
            static_cast<unsigned long long>(n), method.c_str(),
            run.owned_rows_only ? "owned" : "all", median(s[step_phase]), median(s[refresh_phase]),
            median(s[compute_phase]), median(s[exchange_phase]), median(s[step_cpu]),
            median(s[compute_cpu]), static_cast<unsigned long long>(run.pairs),
            static_cast<unsigned long long>(run.halos));
        if (!run.plain.empty())
          std::fprintf(
              stderr,
              "  plain engine build + lj_forces %.3f ms (build %.3f): distributed step / "
              "plain %.3f (rank 0's refresh: update %.3f + halos %.3f + local build %.3f)\n",
              median(run.plain), median(run.plain_build), median(s[step_phase]) / median(run.plain),
              median(run.update), median(run.halo_refresh), median(run.local_build));
        if (!pairs_ok)
          std::fprintf(stderr, "  check failed: %llu pairs, expected %.0f +- 2%%\n",
                       static_cast<unsigned long long>(run.pairs), expected);
      };
      std::string write_error;
      if (rank == 0) try {
          write_row();
        } catch (const Error& e) {
          write_error = e.what();
        }
      int write_failed = !write_error.empty();
      MPI_Bcast(&write_failed, 1, MPI_INT, 0, comm);
      if (write_failed)
        throw Error(ErrorCode::io, rank == 0 ? write_error : "rank 0 cannot write " + out);
    }
  }
  if (rank == 0) {
    csv->commit();
    std::fprintf(stderr, "wrote %s\n", out.c_str());
  }
  return status;
}

}  // namespace raycut::cli
