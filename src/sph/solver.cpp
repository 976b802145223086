#include "raycut/sph/solver.hpp"

#include <chrono>
#include <cmath>
#include <optional>
#include <utility>

#include "raycut/error.hpp"
#include "raycut/tools/device_array.hpp"
#include "sph/host_steps.hpp"
#if defined(RAYCUT_HAVE_CUDA)
#include "sph/device_steps.hpp"
#endif

namespace raycut::sph {
namespace {

using Clock = std::chrono::steady_clock;

double elapsed_ms(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

}  // namespace

// Mueller's pressure term -m (p_i + p_j) / (2 rho_j) grad W estimates grad p / 2 (the arithmetic
// mean halves the interpolant sum m p_j / rho_j grad W), so the weakly compressible mode runs it
// with 2 m: -sum m (p_i + p_j) / rho_j grad W, which divided by rho_i is the consistent, symmetric
// (momentum-conserving) -sum m (p_i + p_j) / (rho_i rho_j) grad W -> -grad p / rho; times the
// lattice's gradient renormalisation. mu is divided by the same factor, so the viscosity term
// mu m (v_j - v_i) / rho_j lap W keeps its value.
KernelOptions force_pass_options(const SphParameters& params) {
  KernelOptions o;
  o.sph_mass = params.particle_mass;
  o.sph_viscosity = params.viscosity;
  if (params.weakly_compressible) {
    const float scale = 2.0f * params.gradient_correction;
    o.sph_mass = scale * params.particle_mass;
    o.sph_viscosity = params.viscosity / scale;
  }
  return o;
}

KernelOptions density_pass_options(const SphParameters& params) {
  KernelOptions o;
  o.sph_mass = params.particle_mass;
  o.sph_viscosity = params.viscosity;
  return o;
}

struct Solver::Impl {
  SphParameters params;
  StepConstants constants;
  Engine engine;
  std::size_t n = 0;
  float skin = 0;
  int frame = 0;
  bool device = false;
  bool structure_current = false;  // the engine's structure is over the current positions
  StepTimes times;

  // Host state (CPU methods).
  std::vector<float> x, v, rho, p;
  std::vector<float> fixed;  // 1 for a fixed boundary particle; empty: none
  // Device state (GPU methods): DeviceArray exists only with CUDA; empty optionals otherwise.
  std::optional<DeviceArray> dx, dv, drho, dp, dfixed;

  explicit Impl(Engine e) : engine(std::move(e)) {}

  float* x_ptr() { return device ? dx->data() : x.data(); }
  float* v_ptr() { return device ? dv->data() : v.data(); }
  float* rho_ptr() { return device ? drho->data() : rho.data(); }
  float* p_ptr() { return device ? dp->data() : p.data(); }
  const float* fixed_ptr() const {
    if (fixed.empty()) return nullptr;
    return device ? dfixed->data() : fixed.data();
  }

  // Density or force of the last run, where the method keeps them (no copy).
  const float* result(bool force) const {
    const ResultsView view = engine.results_view();
    return force ? view.force : view.density;
  }

  // Density (neighbours j != i, then the self term) and pressure at the built positions.
  void density_pass() {
    const float* neighbour_density = nullptr;
    if (n > 0) {
      engine.run(Kernel::sph_density, density_pass_options(params));
      neighbour_density = result(false);
    }
    density_and_pressure(neighbour_density);
    sync();
  }

  void sync() {
#if defined(RAYCUT_HAVE_CUDA)
    if (device) device::synchronize();
#endif
  }

  void density_and_pressure(const float* neighbour_density) {
    if (device) {
#if defined(RAYCUT_HAVE_CUDA)
      device::density_and_pressure(neighbour_density, rho_ptr(), p_ptr(), n, constants);
#endif
      return;
    }
    host::density_and_pressure(neighbour_density, rho.data(), p.data(), n, constants);
  }

  void integrate(const float* force) {
    if (device) {
#if defined(RAYCUT_HAVE_CUDA)
      device::integrate(x_ptr(), v_ptr(), force, rho_ptr(), fixed_ptr(), n, constants);
#endif
      return;
    }
    host::integrate(x.data(), v.data(), force, rho.data(), fixed_ptr(), n, constants);
  }
};

Solver::Solver(const SphScenario& scenario, std::string_view method, float skin) {
  validate(scenario);
  if (!(skin < 0) && !std::isfinite(skin))
    throw Error(ErrorCode::invalid_argument, "skin must be finite");
  impl_ = std::make_unique<Impl>(Engine(method));  // every method computes the SPH kernels
  Impl& s = *impl_;
  s.params = scenario.params;
  s.constants = constants_of(s.params);
  s.n = scenario.position.size() / 3;
  s.skin = skin < 0 ? s.params.smoothing_length : skin;
  s.engine.set_update_policy({s.skin});
  s.device = s.engine.space() == MemorySpace::device;
  const std::vector<float> zeros(s.n, 0.0f);
  s.fixed = scenario.fixed;
  if (s.device && !s.fixed.empty()) s.dfixed.emplace(s.fixed);
  if (s.device) {
    s.dx.emplace(scenario.position);
    s.dv.emplace(scenario.velocity);
    s.drho.emplace(zeros);
    s.dp.emplace(zeros);
  } else {
    s.x = scenario.position;
    s.v = scenario.velocity;
    s.rho = zeros;
    s.p = zeros;
  }
  // The first full build, outside the steps; and rho, p of the initial state (for output).
  s.engine.build({s.x_ptr(), s.n, s.device ? MemorySpace::device : MemorySpace::host},
                 s.params.smoothing_length);
  s.structure_current = true;
  s.density_pass();
}

Solver::~Solver() = default;
Solver::Solver(Solver&&) noexcept = default;
Solver& Solver::operator=(Solver&&) noexcept = default;

void Solver::step() {
  Impl& s = *impl_;
  StepTimes t;
  const MemorySpace space = s.device ? MemorySpace::device : MemorySpace::host;
  const PositionsView positions{s.x_ptr(), s.n, space};

  // 1. The structure over the current positions (already there on the first step: the
  // constructor built it).
  auto start = Clock::now();
  if (!s.structure_current) {
    s.engine.update(positions);
    t.refit = s.engine.last_timings().refit;
  }
  s.structure_current = false;
  t.update_ms = elapsed_ms(start);

  // 2. Density (neighbours j != i, then the self term) and pressure.
  start = Clock::now();
  s.density_pass();
  t.density_ms = elapsed_ms(start);

  // 3. Pressure + viscosity force (not yet divided by rho_i).
  start = Clock::now();
  const float* force = nullptr;
  if (s.n > 0) {
    KernelOptions options = force_pass_options(s.params);
    options.sph = {s.v_ptr(), s.rho_ptr(), s.p_ptr()};
    s.engine.run(Kernel::sph_force, options);
    force = s.result(true);
  }
  t.force_ms = elapsed_ms(start);

  // 4. Walls, gravity, semi-implicit Euler (the settling damping while t < damping_time).
  start = Clock::now();
  s.constants.velocity_keep = velocity_keep_at(s.params, time());
  s.integrate(force);
  s.sync();
  t.integrate_ms = elapsed_ms(start);

  s.times = t;
  ++s.frame;
}

double Solver::time() const {
  return impl_->frame * static_cast<double>(impl_->params.dt);
}
int Solver::frame() const {
  return impl_->frame;
}
std::size_t Solver::size() const {
  return impl_->n;
}
const SphParameters& Solver::parameters() const {
  return impl_->params;
}
const std::string& Solver::method() const {
  return impl_->engine.method();
}
MemorySpace Solver::space() const {
  return impl_->engine.space();
}
float Solver::skin() const {
  return impl_->skin;
}
StepTimes Solver::last_times() const {
  return impl_->times;
}

void Solver::copy_state(std::vector<float>& x, std::vector<float>& v, std::vector<float>& rho,
                        std::vector<float>& p) const {
  const Impl& s = *impl_;
  if (!s.device) {
    x = s.x;
    v = s.v;
    rho = s.rho;
    p = s.p;
    return;
  }
  x.resize(3 * s.n);
  v.resize(3 * s.n);
  rho.resize(s.n);
  p.resize(s.n);
#if defined(RAYCUT_HAVE_CUDA)
  device::copy_to_host(x.data(), s.dx->data(), 3 * s.n);
  device::copy_to_host(v.data(), s.dv->data(), 3 * s.n);
  device::copy_to_host(rho.data(), s.drho->data(), s.n);
  device::copy_to_host(p.data(), s.dp->data(), s.n);
#endif
}

}  // namespace raycut::sph
