// The SPH fluid solver of docs/sph.md on the public interaction engine: any method that computes
// Kernel::sph_density and Kernel::sph_force runs it, with no method-specific code. Per step:
//   1. structure: Engine::build(x, h) once in the constructor, Engine::update(x) at the start of
//      every later step (the OptiX methods refit while no particle has moved more than skin / 2
//      since the last full build, the others rebuild);
//   2. density pass (Kernel::sph_density) + the self term, then the pressure;
//   3. force pass (Kernel::sph_force: pressure + viscosity, inputs v, rho, p);
//   4. integration: a = f / rho, the six wall penalties, gravity, semi-implicit Euler.
// The state (x, v, rho, p) lives where the method works (Engine::space()): on the device for the
// GPU methods, read and written there by small CUDA kernels, with the engine's results read in
// place (no host round trip per step); on the host for the CPU methods, with OpenMP loops. Both
// run the same per-particle arithmetic (src/sph/physics.hpp, internal).
#pragma once

#include <cstddef>
#include <memory>
#include <string>
#include <string_view>
#include <vector>

#include "raycut/engine.hpp"
#include "raycut/sph/scenario.hpp"

namespace raycut::sph {

// Host-clock milliseconds of the last step's passes, each synchronised (device work included).
struct StepTimes {
  double update_ms = 0;     // Engine::update (0 on the first step: the constructor built)
  double density_ms = 0;    // density pass + pressure
  double force_ms = 0;      // pressure + viscosity pass
  double integrate_ms = 0;  // walls, gravity, Euler
  bool refit = false;       // the structure was refitted, not rebuilt
  double total_ms() const { return update_ms + density_ms + force_ms + integrate_ms; }
};

// The KernelOptions (mass, viscosity) of the force pass: the parameters' own in the article's
// model; 2 m gradient_correction and mu / (2 gradient_correction) in the weakly compressible mode
// (solver.cpp says why). The inputs (KernelOptions::sph) are left empty.
KernelOptions force_pass_options(const SphParameters& params);
// The KernelOptions of the density pass (the particle mass).
KernelOptions density_pass_options(const SphParameters& params);

class Solver {
 public:
  // Validates the scenario (sph::validate), creates the engine, builds it over the initial
  // positions and runs one density pass (so copy_state has rho and p of frame 0); no step is
  // taken. `method` is
  // a name of list_methods() or "auto" (raycut::auto_method(): grid with a GPU, else cell-list,
  // also the fastest for SPH, docs/sph.md). skin < 0 picks the default, h: the
  // OptiX methods then refit while no particle has moved more than h / 2 since the last full
  // build; the other methods ignore the skin and rebuild every step. skin = 0 rebuilds always.
  // Throws Error(invalid_argument / unsupported) for a bad scenario, method or skin.
  explicit Solver(const SphScenario& scenario, std::string_view method = "auto", float skin = -1);
  ~Solver();
  Solver(Solver&&) noexcept;
  Solver& operator=(Solver&&) noexcept;

  // One time step of dt.
  void step();

  double time() const;  // frame() * dt
  int frame() const;    // steps taken
  std::size_t size() const;
  const SphParameters& parameters() const;
  const std::string& method() const;
  MemorySpace space() const;
  float skin() const;

  // The state on the host: positions and velocities now; density and pressure of the last
  // density pass (at the positions the last step started from; of the initial positions before
  // the first step).
  void copy_state(std::vector<float>& x, std::vector<float>& v, std::vector<float>& rho,
                  std::vector<float>& p) const;

  StepTimes last_times() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace raycut::sph
