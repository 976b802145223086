// The SPH solver of raycut::sph on the distributed engine (docs/distributed.md, "The SPH solver"):
// each rank steps the particles it owns with the same passes as sph::Solver (density + self term
// + pressure, the force pass, walls + gravity + semi-implicit Euler, the per-particle arithmetic
// shared with it), DistributedEngine gives the halos (positions, and the force pass's velocity,
// density and pressure) and migrates particles with their velocity. A method that works in
// device memory (grid, brute-force-gpu, the OptiX methods) keeps the whole step on the GPU: a
// device-resident engine, sph::Solver's CUDA steps, the halo fields by the refreshes' transport.
// Library: raycut::sph_mpi (raycut::sph and raycut::mpi; raycut::mpi alone has no SPH).
//
//   raycut::mpi::SphSolver solver(MPI_COMM_WORLD, raycut::sph::hiprt_drop(), "cell-list");
//   for (int f = 0; f < 200; ++f) solver.step();
//   solver.copy_state(x, v, rho, p);  // collective; rank 0 gets them by global index
#pragma once

#include <mpi.h>

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "raycut/mpi/distributed.hpp"
#include "raycut/sph/scenario.hpp"
#include "raycut/sph/solver.hpp"

namespace raycut::mpi {

// The run so far over all ranks (SphSolver::statistics).
struct SphRunStats {
  int ranks = 1;
  std::array<int, 3> dims = {1, 1, 1};
  std::uint64_t owned_min = 0, owned_max = 0;  // particles per rank now
  std::uint64_t halos = 0;                     // summed over the ranks, now
  double halos_mean = 0;                       // the same, averaged over the steps
  std::uint64_t exchanges = 0;  // steps whose update() exchanged (migration, new halos)
  std::uint64_t refreshes = 0;  // steps whose update() refreshed the halos in place
  std::uint64_t migrated = 0;   // particles sent to another rank by those exchanges, summed
  std::uint64_t balances = 0;   // exchanges that moved the cuts (build's included; Balance)
};

class SphSolver {
 public:
  // Collective. Every rank passes the same scenario (sph::validate'd); rank r hands particles
  // [r N / P, (r + 1) N / P) to DistributedEngine::build, which sends each to its domain's rank.
  // The box is open (the pool's walls are penalties): the domains split the particles' extent at
  // build along each axis (dims; 0 entries: MPI_Dims_create), the end slabs reach to infinity.
  // `method`: any method, or "auto" (auto_method(): the GPU grid where there is a GPU, else the
  // cell list). `skin`: halos reach h + skin and are
  // refreshed in place while no particle has moved more than skin / 2 since the last exchange;
  // < 0: h / 2. `balance`, `rebalance_every`: DistributedOptions' (the cuts at the particle-count
  // quantiles at build and every rebalance_every-th exchange; the water moves). Then one density
  // pass (copy_state has rho and p of frame 0), as sph::Solver. `transport`:
  // DistributedOptions::transport (make_nccl_transport: a device method's halo refreshes and
  // fields GPU to GPU; null: host-staged MPI).
  // Errors as sph::Solver's and DistributedEngine::build's, thrown on every rank.
  SphSolver(MPI_Comm comm, const sph::SphScenario& scenario, std::string_view method = "auto",
            float skin = -1, std::array<int, 3> dims = {0, 0, 0}, Balance balance = Balance::none,
            int rebalance_every = 0, std::shared_ptr<Transport> transport = nullptr);
  ~SphSolver();
  SphSolver(const SphSolver&) = delete;
  SphSolver& operator=(const SphSolver&) = delete;

  // Collective: one time step of dt.
  void step();

  double time() const;  // frame() * dt
  int frame() const;
  std::size_t size() const;  // N over all ranks
  const sph::SphParameters& parameters() const;
  const std::string& method() const;
  // Where the particles' state lives: the method's space.
  MemorySpace space() const;
  float skin() const;

  // Collective: the global state on `root` by global index, as sph::Solver::copy_state gives it
  // (positions and velocities now; density and pressure of the last density pass); the other
  // ranks' vectors are emptied. Error(internal) on every rank unless each index is there once.
  void copy_state(std::vector<float>& x, std::vector<float>& v, std::vector<float>& rho,
                  std::vector<float>& p, int root = 0) const;

  // The last step's passes, each the largest over the ranks (step() ends with one
  // MPI_Allreduce, so a rank's clock around step() reads the slowest rank's step). update_ms is
  // DistributedEngine::update (halo refresh or exchange, local builds), force_ms includes the halo
  // fields' exchange; refit: the halos were refreshed in place, not exchanged.
  sph::StepTimes last_times() const;
  // Collective.
  SphRunStats statistics() const;

  // Which particles this rank owns (ids()), its halos, the decomposition.
  const DistributedEngine& engine() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace raycut::mpi
