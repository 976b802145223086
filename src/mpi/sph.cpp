#include "raycut/mpi/sph.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <limits>
#include <numeric>
#include <utility>

#include "mpi/mpi_check.hpp"
#include "mpi/sph_device.hpp"
#include "raycut/error.hpp"
#include "sph/host_steps.hpp"

namespace raycut::mpi {
namespace {

using Clock = std::chrono::steady_clock;

double elapsed_ms(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

int checked_int(std::size_t n, const char* what) {
  if (n > static_cast<std::size_t>(std::numeric_limits<int>::max()))
    throw Error(ErrorCode::unsupported,
                std::string("distributed sph: ") + what + " exceeds an MPI count (int)");
  return static_cast<int>(n);
}

// The state of a device-resident run: asked for by methods that work on the device only, which
// builds without CUDA do not have.
std::unique_ptr<detail::SphDevice> sph_device() {
#if defined(RAYCUT_HAVE_CUDA)
  return detail::make_sph_device();
#else
  throw Error(ErrorCode::internal, "a device-resident SPH solver in a build without CUDA");
#endif
}

}  // namespace

struct SphSolver::Impl {
  MPI_Comm comm;
  sph::SphParameters params;
  sph::StepConstants constants;
  DistributedEngine engine;
  std::string method;
  float skin = 0;
  bool with_fixed = false;  // the scenario has fixed boundary particles: carried with v
  int frame = 0;
  bool structure_current = false;  // the engine's halos are over the current positions
  sph::StepTimes times;
  std::uint64_t exchanges = 0, refreshes = 0, migrated = 0;
  double halo_sum = 0;  // this rank's halos summed over the steps

  // The owned particles in engine.ids() order: on the host, or with a method that works in
  // device memory in `device` (the engine is then device-resident: the step stays on the GPU).
  std::unique_ptr<detail::SphDevice> device;
  std::vector<float> x, v, rho, p, fixed;
  std::vector<float> carried;  // v (and fixed) packed for the engine, width() per particle

  Impl(MPI_Comm c, const DistributedOptions& options)
      : comm(c), engine(c, options), method(options.method), skin(options.skin) {}

  std::size_t width() const { return with_fixed ? 4 : 3; }

  // What travels with a particle on migration: its velocity and, in the weakly compressible
  // mode, whether it is a fixed boundary particle.
  const float* pack() {
    const std::size_t n = x.size() / 3, w = width();
    carried.resize(w * n);
    for (std::size_t i = 0; i < n; ++i) {
      std::copy_n(&v[3 * i], 3, &carried[w * i]);
      if (with_fixed) carried[w * i + 3] = fixed[i];
    }
    return carried.data();
  }

  // After an exchange the owned set and order changed: read them back from the engine.
  void take_owned() {
    if (device) {
      device->take(engine.owned_positions().xyz, engine.owned_carried(), engine.owned());
      return;
    }
    const std::size_t n = engine.owned(), w = width();
    x = engine.positions();
    const std::vector<float>& c = engine.carried();
    v.resize(3 * n);
    fixed.resize(with_fixed ? n : 0);
    for (std::size_t i = 0; i < n; ++i) {
      std::copy_n(&c[w * i], 3, &v[3 * i]);
      if (with_fixed) fixed[i] = c[w * i + 3];
    }
    rho.assign(n, 0.0f);
    p.assign(n, 0.0f);
  }

  // Density (neighbours j != i, owned rows, then the self term) and pressure.
  void density_pass() {
    if (device) {
      const ResultsView r = engine.run(Kernel::sph_density, sph::density_pass_options(params));
      device->density_and_pressure(engine.owned() > 0 ? r.density : nullptr, constants);
      return;
    }
    const Results r = engine.compute(Kernel::sph_density, sph::density_pass_options(params));
    sph::host::density_and_pressure(r.density.empty() ? nullptr : r.density.data(), rho.data(),
                                    p.data(), engine.owned(), constants);
  }
};

namespace {

// The sph::Solver's checks first (the same scenario on every rank, so every rank throws alike).
DistributedOptions options_of(const sph::SphScenario& scenario, std::string_view method, float skin,
                              std::array<int, 3> dims, Balance balance, int rebalance_every,
                              std::shared_ptr<Transport> transport) {
  sph::validate(scenario);
  if (!(skin < 0) && !std::isfinite(skin))
    throw Error(ErrorCode::invalid_argument, "skin must be finite");
  DistributedOptions o;
  // "auto": the GPU grid where there is a GPU (the step on the device), else the cell list.
  o.method = method == "auto" ? auto_method() : std::string(method);
  o.skin = skin < 0 ? 0.5f * scenario.params.smoothing_length : skin;
  o.dims = dims;
  o.balance = balance;
  o.rebalance_every = rebalance_every;
  o.transport = std::move(transport);
  return o;
}

}  // namespace

SphSolver::SphSolver(MPI_Comm comm, const sph::SphScenario& scenario, std::string_view method,
                     float skin, std::array<int, 3> dims, Balance balance, int rebalance_every,
                     std::shared_ptr<Transport> transport)
    : impl_(std::make_unique<Impl>(comm, options_of(scenario, method, skin, dims, balance,
                                                    rebalance_every, std::move(transport)))) {
  Impl& s = *impl_;
  s.params = scenario.params;
  s.constants = sph::constants_of(s.params);
  s.with_fixed = !scenario.fixed.empty();
  int rank = 0, size = 1;
  check(MPI_Comm_rank(comm, &rank), "MPI_Comm_rank");
  check(MPI_Comm_size(comm, &size), "MPI_Comm_size");
  // This rank's contiguous share; the build sends each particle to its domain.
  const std::size_t n = scenario.position.size() / 3;
  const std::size_t first = n * rank / size, last = n * (rank + 1) / size;
  std::vector<std::uint64_t> ids(last - first);
  std::iota(ids.begin(), ids.end(), std::uint64_t{first});
  s.x.assign(scenario.position.begin() + 3 * first, scenario.position.begin() + 3 * last);
  s.v.assign(scenario.velocity.begin() + 3 * first, scenario.velocity.begin() + 3 * last);
  if (s.with_fixed) s.fixed.assign(scenario.fixed.begin() + first, scenario.fixed.begin() + last);
  if (s.engine.local_engine().space() == MemorySpace::device) {
    s.device = sph_device();
    s.device->upload(s.x, s.v, s.fixed, s.with_fixed);
    s.engine.build({s.device->x(), ids.size(), MemorySpace::device}, ids.data(),
                   s.params.smoothing_length, Box::open(), s.device->pack(), s.width());
  } else {
    s.engine.build({s.x.data(), ids.size(), MemorySpace::host}, ids.data(),
                   s.params.smoothing_length, Box::open(), s.pack(), s.width());
  }
  s.take_owned();
  s.structure_current = true;
  s.density_pass();
}

SphSolver::~SphSolver() = default;

void SphSolver::step() {
  Impl& s = *impl_;
  sph::StepTimes t;

  // 1. Halos over the current positions (the constructor's build on the first step): a refresh
  // in place within the skin, else an exchange that migrates particles with their velocity.
  auto start = Clock::now();
  if (!s.structure_current) {
    const std::uint64_t before = s.engine.stats().exchanges;
    const bool exchanged = s.device ? s.engine.update(s.device->x(), s.device->pack())
                                    : s.engine.update(s.x.data(), s.pack());
    if (exchanged) s.take_owned();
    if (s.engine.stats().exchanges != before) {
      ++s.exchanges;
      s.migrated += s.engine.stats().migrated_out;
    } else {
      ++s.refreshes;
      t.refit = true;
    }
  }
  s.structure_current = false;
  s.halo_sum += static_cast<double>(s.engine.halos());
  t.update_ms = elapsed_ms(start);

  // 2. Density and pressure of the owned particles.
  start = Clock::now();
  s.density_pass();
  t.density_ms = elapsed_ms(start);

  // 3. Pressure + viscosity force; the engine sends the fields' halo copies.
  start = Clock::now();
  const SphFields fields = s.device ? SphFields{s.device->v(), s.device->rho(), s.device->p()}
                                    : SphFields{s.v.data(), s.rho.data(), s.p.data()};
  const ResultsView f = s.engine.run(Kernel::sph_force, sph::force_pass_options(s.params), fields);
  const float* force = s.engine.owned() > 0 ? f.force : nullptr;
  t.force_ms = elapsed_ms(start);

  // 4. Walls, gravity, semi-implicit Euler on the owned particles.
  start = Clock::now();
  s.constants.velocity_keep = sph::velocity_keep_at(s.params, time());
  if (s.device)
    s.device->integrate(force, s.constants);
  else
    sph::host::integrate(s.x.data(), s.v.data(), force, s.rho.data(),
                         s.with_fixed ? s.fixed.data() : nullptr, s.engine.owned(), s.constants);
  t.integrate_ms = elapsed_ms(start);

  // The slowest rank's passes (also a barrier: the step ends when every rank's has).
  double mine[4] = {t.update_ms, t.density_ms, t.force_ms, t.integrate_ms}, largest[4];
  check(MPI_Allreduce(mine, largest, 4, MPI_DOUBLE, MPI_MAX, s.comm), "MPI_Allreduce");
  t.update_ms = largest[0];
  t.density_ms = largest[1];
  t.force_ms = largest[2];
  t.integrate_ms = largest[3];
  s.times = t;
  ++s.frame;
}

double SphSolver::time() const {
  return impl_->frame * static_cast<double>(impl_->params.dt);
}
int SphSolver::frame() const {
  return impl_->frame;
}
std::size_t SphSolver::size() const {
  return impl_->engine.global_size();
}
const sph::SphParameters& SphSolver::parameters() const {
  return impl_->params;
}
const std::string& SphSolver::method() const {
  return impl_->method;
}
MemorySpace SphSolver::space() const {
  return impl_->device ? MemorySpace::device : MemorySpace::host;
}
float SphSolver::skin() const {
  return impl_->skin;
}
sph::StepTimes SphSolver::last_times() const {
  return impl_->times;
}
const DistributedEngine& SphSolver::engine() const {
  return impl_->engine;
}

void SphSolver::copy_state(std::vector<float>& x, std::vector<float>& v, std::vector<float>& rho,
                           std::vector<float>& p, int root) const {
  const Impl& s = *impl_;
  const DistributedEngine& e = s.engine;
  std::vector<float> dx, dv, drho, dp;  // a device-resident run's, downloaded
  if (s.device) s.device->download(dx, dv, drho, dp);
  const std::vector<float>& ox = s.device ? dx : s.x;
  const std::vector<float>& ov = s.device ? dv : s.v;
  const std::vector<float>& orho = s.device ? drho : s.rho;
  const std::vector<float>& op = s.device ? dp : s.p;
  // 8 floats per particle: x, v, rho, p.
  const std::size_t n = e.owned();
  std::vector<float> mine(8 * n);
  for (std::size_t i = 0; i < n; ++i) {
    std::copy_n(&ox[3 * i], 3, &mine[8 * i]);
    std::copy_n(&ov[3 * i], 3, &mine[8 * i + 3]);
    mine[8 * i + 6] = orho[i];
    mine[8 * i + 7] = op[i];
  }
  checked_int(8 * e.global_size(), "8 floats per particle, over all ranks,");
  const int count = static_cast<int>(8 * n);
  const bool at_root = e.rank() == root;
  std::vector<int> counts(at_root ? e.size() : 0), offsets(counts.size());
  check(MPI_Gather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, root, s.comm), "MPI_Gather");
  std::vector<int> id_counts(counts.size()), id_offsets(counts.size());
  for (std::size_t r = 0; r < counts.size(); ++r) {
    id_counts[r] = counts[r] / 8;
    if (r > 0) {
      offsets[r] = offsets[r - 1] + counts[r - 1];
      id_offsets[r] = id_offsets[r - 1] + id_counts[r - 1];
    }
  }
  const std::size_t total =
      at_root ? static_cast<std::size_t>(id_offsets.back() + id_counts.back()) : 0;
  std::vector<std::uint64_t> ids(total);
  std::vector<float> all(8 * total);
  check(MPI_Gatherv(e.ids().data(), count / 8, MPI_UINT64_T, ids.data(), id_counts.data(),
                    id_offsets.data(), MPI_UINT64_T, root, s.comm),
        "MPI_Gatherv");
  check(MPI_Gatherv(mine.data(), count, MPI_FLOAT, all.data(), counts.data(), offsets.data(),
                    MPI_FLOAT, root, s.comm),
        "MPI_Gatherv");

  const std::size_t global = e.global_size();
  x.assign(at_root ? 3 * global : 0, 0.0f);
  v.assign(at_root ? 3 * global : 0, 0.0f);
  rho.assign(at_root ? global : 0, 0.0f);
  p.assign(at_root ? global : 0, 0.0f);
  // Each global index exactly once: particles are neither lost nor duplicated by migration.
  int wrong = 0;
  if (at_root) {
    std::vector<bool> seen(global, false);
    wrong = total != global;
    for (std::size_t k = 0; k < total && !wrong; ++k) {
      const std::uint64_t id = ids[k];
      if (id >= global || seen[id]) {
        wrong = 1;
        break;
      }
      seen[id] = true;
      std::copy_n(&all[8 * k], 3, &x[3 * id]);
      std::copy_n(&all[8 * k + 3], 3, &v[3 * id]);
      rho[id] = all[8 * k + 6];
      p[id] = all[8 * k + 7];
    }
  }
  check(MPI_Bcast(&wrong, 1, MPI_INT, root, s.comm), "MPI_Bcast");
  if (wrong)
    throw Error(ErrorCode::internal,
                "distributed sph: the gathered particles are not each "
                "global index once (lost or duplicated in migration)");
}

SphRunStats SphSolver::statistics() const {
  const Impl& s = *impl_;
  const DistributedEngine& e = s.engine;
  SphRunStats r;
  r.ranks = e.size();
  r.dims = e.decomposition().dims;
  r.exchanges = s.exchanges;  // the same on every rank (update() agrees)
  r.refreshes = s.refreshes;
  r.balances = e.stats().balances;  // the same on every rank
  const std::uint64_t owned = e.owned();
  std::uint64_t sums[2] = {e.halos(), s.migrated}, totals[2];
  double halo_sum = 0;
  check(MPI_Allreduce(sums, totals, 2, MPI_UINT64_T, MPI_SUM, s.comm), "MPI_Allreduce");
  check(MPI_Allreduce(&s.halo_sum, &halo_sum, 1, MPI_DOUBLE, MPI_SUM, s.comm), "MPI_Allreduce");
  check(MPI_Allreduce(&owned, &r.owned_min, 1, MPI_UINT64_T, MPI_MIN, s.comm), "MPI_Allreduce");
  check(MPI_Allreduce(&owned, &r.owned_max, 1, MPI_UINT64_T, MPI_MAX, s.comm), "MPI_Allreduce");
  r.halos = totals[0];
  r.migrated = totals[1];
  r.halos_mean = s.frame > 0 ? halo_sum / s.frame : static_cast<double>(r.halos);
  return r;
}

}  // namespace raycut::mpi
