// Lennard-Jones molecular dynamics on the distributed engine, under mpirun: an FCC crystal at
// density 0.8442 melting in a periodic cube (reduced units: mass, epsilon and sigma 1, rc 2.5),
// velocity Verlet with the velocities carried by the engine when particles migrate between
// domains. Prints the total energy per particle (the potential shifted to 0 at rc, so that a pair
// crossing the cutoff does not jump it) and exits 1 when it drifts more than --max-drift per
// particle, or (on more than one rank) when no particle migrated.
//
//   mpirun -np 2 raycut_lj_md --cells 6 --steps 100 --max-drift 2e-3
#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "raycut/mpi/distributed.hpp"

namespace {

struct Options {
  int cells = 6;  // FCC unit cells per side: 4 cells^3 particles
  int steps = 100;
  double dt = 0.005, temperature = 1.44, skin = 0.3, max_drift = 0;  // 0: report only
  int every = 10;                                                    // energy printed every
  std::string method = "cell-list";
};

Options parse(int argc, char** argv) {
  Options o;
  for (int k = 1; k + 1 < argc; k += 2) {
    const std::string key = argv[k];
    const char* value = argv[k + 1];
    if (key == "--cells")
      o.cells = std::atoi(value);
    else if (key == "--steps")
      o.steps = std::atoi(value);
    else if (key == "--dt")
      o.dt = std::atof(value);
    else if (key == "--temperature")
      o.temperature = std::atof(value);
    else if (key == "--skin")
      o.skin = std::atof(value);
    else if (key == "--max-drift")
      o.max_drift = std::atof(value);
    else if (key == "--every")
      o.every = std::atoi(value);
    else if (key == "--method")
      o.method = value;
    else
      throw std::runtime_error("unknown option " + key);
  }
  if (o.cells < 1 || o.steps < 1 || !(o.dt > 0) || o.every < 1)
    throw std::runtime_error("--cells, --steps, --dt and --every must be positive");
  return o;
}

constexpr float cutoff = 2.5f;

// Kinetic and shifted potential energy summed over all ranks: U = 1/2 sum_i (e_i - n_i U(rc)),
// each pair seen from both ends.
double total_energy(raycut::mpi::DistributedEngine& engine, const raycut::Results& lj,
                    const std::vector<float>& v, double& kinetic) {
  const raycut::Results count = engine.compute(raycut::Kernel::count);
  const double rc6 = std::pow(static_cast<double>(cutoff), -6.0);
  const double at_cutoff = 4 * rc6 * (rc6 - 1);
  double mine[2] = {0, 0}, sum[2];
  for (std::size_t t = 0; t < engine.owned(); ++t)
    mine[0] += 0.5 * (lj.energy[t] - count.count[t] * at_cutoff);
  for (float x : v) mine[1] += 0.5 * static_cast<double>(x) * x;
  MPI_Allreduce(mine, sum, 2, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  kinetic = sum[1];
  return sum[0] + sum[1];
}

int run(const Options& o) {
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
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
  engine.build({xyz.data(), ids.size(), raycut::MemorySpace::host}, ids.data(), cutoff,
               raycut::Box::orthorhombic(side, side, side), v.data(), 3);
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
  for (int step = 1; step <= o.steps; ++step) {
    // Kick, drift, then the engine moves what left its domain (with its velocity) or refreshes
    // the halos; forces at the new positions, kick.
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
    const double e = total_energy(engine, lj, v, kinetic);
    worst = std::max(worst, std::abs(e - e0) / n);
    if (rank == 0)
      std::printf("step %4d  E/N %.6f  KE/N %.6f  T %.4f  exchanges %llu  refreshes %llu\n", step,
                  e / n, kinetic / n, 2 * kinetic / (3.0 * (n - 1)),
                  static_cast<unsigned long long>(engine.stats().exchanges),
                  static_cast<unsigned long long>(engine.stats().refreshes));
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
  } catch (const std::exception& e) {
    std::fprintf(stderr, "lj_md: %s\n", e.what());
  }
  MPI_Finalize();
  return status;
}
