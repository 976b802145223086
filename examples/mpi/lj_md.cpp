// Lennard-Jones molecular dynamics on the distributed engine, under mpirun: an FCC crystal at
// density 0.8442 melting in a periodic cube (reduced units: mass, epsilon and sigma 1, rc 2.5),
// velocity Verlet with the velocities carried by the engine when particles migrate between
// domains. Prints the total energy per particle (the potential shifted to 0 at rc, so that a pair
// crossing the cutoff does not jump it) and exits 1 when it drifts more than --max-drift per
// particle, or (on more than one rank) when no particle migrated.
//
//   mpirun -np 2 raycut_lj_md --cells 6 --steps 100 --max-drift 2e-3
//   mpirun -np 2 raycut_lj_md --device --method grid ...   (the step loop on the GPU)
#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "raycut/mpi/distributed.hpp"

#include <CLI/CLI.hpp>
#if defined(LJ_MD_CUDA)
#include "verlet.hpp"
#endif

namespace {

struct Options {
  int cells = 6;  // FCC unit cells per side: 4 cells^3 particles
  int steps = 100;
  double dt = 0.005, temperature = 1.44, skin = 0.3, max_drift = 0;  // 0: report only
  int every = 10;                                                    // energy printed every
  std::string method = "cell-list";
  bool device = false;
};

// Throws CLI::ParseError (main prints it and exits with its code).
Options parse(int argc, char** argv) {
  Options o;
  CLI::App app("Lennard-Jones MD on raycut::mpi::DistributedEngine (run under mpirun)");
  const auto positive = CLI::Range(1, std::numeric_limits<int>::max());
  app.add_option("--cells", o.cells, "FCC unit cells per side (4 cells^3 particles)")
      ->check(positive);
  app.add_option("--steps", o.steps, "velocity Verlet steps")->check(positive);
  app.add_option("--dt", o.dt, "time step")->check(CLI::PositiveNumber);
  app.add_option("--temperature", o.temperature, "initial temperature")->check(CLI::PositiveNumber);
  app.add_option("--skin", o.skin, "halo skin (DistributedOptions::skin)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--max-drift", o.max_drift, "fail above this |E - E0| / N (0: report only)")
      ->check(CLI::NonNegativeNumber);
  app.add_option("--every", o.every, "energy printed every this many steps")->check(positive);
  app.add_option("--method", o.method, "the local engines' method");
  app.add_flag("--device", o.device,
               "positions, velocities and forces on the GPU (a device-resident engine, a GPU "
               "method, the integrator's kernels in verlet.cu); exits 77 without a CUDA device");
  app.parse(argc, argv);
  return o;
}

constexpr float cutoff = 2.5f;

// Kinetic and shifted potential energy summed over all ranks: U = sum_i (e_i - 1/2 n_i U(rc)),
// e_i holding half of each of its n_i pairs' energy (lj_forces' convention).
double total_energy(raycut::mpi::DistributedEngine& engine, const raycut::Results& lj,
                    const std::vector<float>& v, double& kinetic) {
  const raycut::Results count = engine.compute(raycut::Kernel::count);
  const double rc6 = std::pow(static_cast<double>(cutoff), -6.0);
  const double at_cutoff = 4 * rc6 * (rc6 - 1);
  double mine[2] = {0, 0}, sum[2];
  for (std::size_t t = 0; t < engine.owned(); ++t)
    mine[0] += lj.energy[t] - 0.5 * count.count[t] * at_cutoff;
  for (float x : v) mine[1] += 0.5 * static_cast<double>(x) * x;
  MPI_Allreduce(mine, sum, 2, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  kinetic = sum[1];
  return sum[0] + sum[1];
}

constexpr int skipped = 77;  // ctest's SKIP_RETURN_CODE

int run(const Options& o) {
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  if (o.device) {
#if defined(LJ_MD_CUDA)
    if (raycut::mpi::select_local_device(MPI_COMM_WORLD) < 0 || !lj_md::have_device()) {
      if (rank == 0) std::printf("lj_md --device: no CUDA device, skipped\n");
      return skipped;
    }
#else
    throw std::runtime_error("--device: this build has no CUDA");
#endif
  }
  const double a = std::cbrt(4 / 0.8442), side = o.cells * a;
  const std::size_t n = 4 * static_cast<std::size_t>(o.cells) * o.cells * o.cells;

  // Every rank makes the same crystal and velocities (one seed) and gives every size-th
  // particle to build(), which sends each to its domain.
  static constexpr double basis[4][3] = {{0, 0, 0}, {0.5, 0.5, 0}, {0.5, 0, 0.5}, {0, 0.5, 0.5}};
  std::vector<double> velocity(3 * n);
  std::mt19937_64 rng(2024);
  std::normal_distribution<double> gauss(0.0, 1.0);
  double mean[3] = {0, 0, 0}, squares = 0;
  for (std::size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) {
      velocity[3 * i + c] = gauss(rng);
      mean[c] += velocity[3 * i + c] / n;
    }
  for (std::size_t i = 0; i < n; ++i)
    for (int c = 0; c < 3; ++c) squares += std::pow(velocity[3 * i + c] - mean[c], 2);
  const double scale = std::sqrt(o.temperature * 3.0 * (n - 1) / squares);  // no drift, T exact
  std::vector<float> xyz, v;
  std::vector<std::uint64_t> ids;
  for (std::size_t i = 0; i < n; ++i) {
    if (static_cast<int>(i % size) != rank) continue;
    const std::size_t cell = i / 4, b = i % 4;
    const std::size_t at[3] = {cell % o.cells, cell / o.cells % o.cells, cell / o.cells / o.cells};
    ids.push_back(i);
    for (int c = 0; c < 3; ++c) {
      xyz.push_back(static_cast<float>((at[c] + basis[b][c] + 0.05) * a));  // near the faces
      v.push_back(static_cast<float>((velocity[3 * i + c] - mean[c]) * scale));
    }
  }

  raycut::mpi::DistributedOptions options;
  options.method = o.method;
  options.skin = static_cast<float>(o.skin);
  raycut::mpi::DistributedEngine engine(MPI_COMM_WORLD, options);
  const raycut::Box box = raycut::Box::orthorhombic(side, side, side);
#if defined(LJ_MD_CUDA)
  // --device: the same step on the GPU. x and v are given in device memory, so the engine keeps
  // positions, velocities (carried), halos and forces there; update() plans exchanges there.
  lj_md::DeviceFloats d_x, d_v;
  if (o.device) {
    d_x.upload(xyz.data(), xyz.size());
    d_v.upload(v.data(), v.size());
    engine.build({d_x.data(), ids.size(), raycut::MemorySpace::device}, ids.data(), cutoff, box,
                 d_v.data(), 3);
  } else
#endif
    engine.build({xyz.data(), ids.size(), raycut::MemorySpace::host}, ids.data(), cutoff, box,
                 v.data(), 3);
  v = engine.carried();
  raycut::Results lj = engine.compute(raycut::Kernel::lj_forces);
  double kinetic = 0;
  const double e0 = total_energy(engine, lj, v, kinetic);
  if (rank == 0)
    std::printf("lj_md: %zu particles, side %.4f, %d ranks (dims %d %d %d), dt %g, skin %g\n", n,
                side, size, engine.decomposition().dims[0], engine.decomposition().dims[1],
                engine.decomposition().dims[2], o.dt, o.skin);

  double worst = 0;  // the largest |E - E0| / N
  std::uint64_t migrated = 0;
  const float dt = static_cast<float>(o.dt), half = 0.5f * dt;
#if defined(LJ_MD_CUDA)
  // The forces of the device loop: run()'s, on the GPU, in owned order.
  const float* force = o.device ? engine.run(raycut::Kernel::lj_forces).force : nullptr;
  if (o.device) d_v.copy(engine.owned_carried(), 3 * engine.owned());
#endif
  for (int step = 1; step <= o.steps; ++step) {
    // Kick, drift, then the engine moves what left its domain (with its velocity) or refreshes
    // the halos; forces at the new positions, kick.
#if defined(LJ_MD_CUDA)
    if (o.device) {  // the owned order changes at an exchange: v is read back from carried
      const std::size_t owned = engine.owned();
      d_x.resize(3 * owned);
      lj_md::kick_drift(engine.owned_positions().xyz, d_v.data(), force, owned, half, dt,
                        d_x.data(), d_v.data());
      if (engine.update(d_x.data(), d_v.data())) migrated += engine.stats().migrated_out;
      force = engine.run(raycut::Kernel::lj_forces).force;
      d_v.resize(3 * engine.owned());
      lj_md::kick(engine.owned_carried(), force, engine.owned(), half, d_v.data());
      if (step % o.every != 0 && step != o.steps) continue;
      lj = engine.compute(raycut::Kernel::lj_forces);  // host copies, for the energy
      v.resize(3 * engine.owned());
      d_v.download(v.data(), v.size());
    } else
#endif
    {
      std::vector<float> x = engine.positions();
      for (std::size_t k = 0; k < v.size(); ++k) {
        v[k] += half * lj.force[k];
        x[k] += dt * v[k];
      }
      if (engine.update(x.data(), v.data())) migrated += engine.stats().migrated_out;
      v = engine.carried();
      lj = engine.compute(raycut::Kernel::lj_forces);
      for (std::size_t k = 0; k < v.size(); ++k) v[k] += half * lj.force[k];
      if (step % o.every != 0 && step != o.steps) continue;
    }
    const double e = total_energy(engine, lj, v, kinetic);
    worst = std::max(worst, std::abs(e - e0) / n);
    if (rank == 0)
      std::printf("step %4d  E/N %.6f  KE/N %.6f  T %.4f  exchanges %llu  refreshes %llu\n", step,
                  e / n, kinetic / n, 2 * kinetic / (3.0 * (n - 1)),
                  static_cast<unsigned long long>(engine.stats().exchanges),
                  static_cast<unsigned long long>(engine.stats().refreshes));
#if defined(LJ_MD_CUDA)
    // compute() and its count invalidate run()'s arrays: the forces again (same positions).
    if (o.device) force = engine.run(raycut::Kernel::lj_forces).force;
#endif
  }
  std::uint64_t total_migrated = 0;
  MPI_Allreduce(&migrated, &total_migrated, 1, MPI_UINT64_T, MPI_SUM, MPI_COMM_WORLD);
  const bool drift_ok = o.max_drift == 0 || worst <= o.max_drift;
  const bool migration_ok = size == 1 || total_migrated > 0;
  if (rank == 0)
    std::printf("largest |E - E0| / N = %.3g (limit %g): %s; %llu particles migrated: %s\n", worst,
                o.max_drift, drift_ok ? "ok" : "FAILED",
                static_cast<unsigned long long>(total_migrated), migration_ok ? "ok" : "FAILED");
  return drift_ok && migration_ok ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int status = 2;
  try {
    status = run(parse(argc, argv));
  } catch (const CLI::ParseError& e) {
    status = e.get_exit_code();
    std::fprintf(stderr, "lj_md: %s\n", e.what());
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lj_md: %s\n", e.what());
  }
  MPI_Finalize();
  return status;
}
