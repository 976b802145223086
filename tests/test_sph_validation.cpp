// The weakly compressible SPH mode (docs/sph-validation.md): Tait's equation of state, the time
// step's three conditions, the consistent pressure gradient of the force pass on a lattice, fixed
// boundary particles that never move, the scenario file, and a tiny hydrostatic column whose
// pressure grows with depth at about rho0 g. Fast on the CPU (cell-list): CI.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "raycut/engine.hpp"
#include "raycut/error.hpp"
#include "raycut/sph/scenario.hpp"
#include "raycut/sph/solver.hpp"
#include "sph/physics.hpp"

namespace raycut::sph {
namespace {

StepConstants tait_constants(float c0, float rho0, bool clamp) {
  StepConstants c{};
  c.rest_density = rho0;
  c.equation_of_state = eos_tait;
  c.tait_b = c0 * c0 * rho0 / 7.0f;
  c.clamp_negative = clamp ? 1 : 0;
  return c;
}

TEST(SphValidation, TaitEquationOfState) {
  const float c0 = 20.0f, rho0 = 1000.0f, b = c0 * c0 * rho0 / 7.0f;
  const StepConstants keep = tait_constants(c0, rho0, false);
  const StepConstants clamp = tait_constants(c0, rho0, true);
  EXPECT_EQ(pressure_of(rho0, keep), 0.0f);
  for (float ratio : {1.001f, 1.01f, 1.05f, 0.99f, 0.9f}) {
    const double expect = b * (std::pow(double{ratio}, 7.0) - 1.0);
    EXPECT_NEAR(pressure_of(ratio * rho0, keep), expect, 1e-4 * b) << ratio;
    EXPECT_NEAR(pressure_of(ratio * rho0, clamp), std::max(expect, 0.0), 1e-4 * b) << ratio;
  }
  // dp/drho at rho0 is c0^2.
  EXPECT_NEAR(pressure_of(1.0001f * rho0, keep) / (0.0001f * rho0), c0 * c0, 0.01 * c0 * c0);
  // The article's law is untouched.
  StepConstants article{};
  article.rest_density = rho0;
  article.stiffness = 200.0f;
  article.equation_of_state = eos_article;
  EXPECT_EQ(pressure_of(1.1f * rho0, article), 200.0f * (1.1f * 1.1f * 1.1f - 1.0f));
  EXPECT_EQ(pressure_of(0.9f * rho0, article), 0.0f);
}

TEST(SphValidation, TimeStepObeysTheThreeConditions) {
  const float h = 0.02f, c0 = 20.0f, vmax = 3.0f, amax = 50.0f, rho0 = 1000.0f, mu = 0.5f;
  const TimeStepLimits t = wcsph_time_step(h, c0, vmax, amax, rho0, mu);
  const double hm = 0.5 * h;
  EXPECT_NEAR(t.cfl, 0.25 * hm / (c0 + vmax), 1e-12);
  EXPECT_NEAR(t.force, 0.25 * std::sqrt(hm / amax), 1e-12);
  EXPECT_NEAR(t.viscous, 0.125 * hm * hm * rho0 / mu, 1e-12);
  EXPECT_LE(t.dt(), t.cfl);
  EXPECT_LE(t.dt(), t.force);
  EXPECT_LE(t.dt(), t.viscous);
  // A viscous-limited case picks the viscous condition.
  EXPECT_EQ(wcsph_time_step(h, c0, 0, 0, rho0, 1e4f).dt(),
            wcsph_time_step(h, c0, 0, 0, rho0, 1e4f).viscous);

  // The scenarios' fixed dt obeys all three for |v| <= c0 / 10 and |a| <= 100 g.
  for (const char* name : {"dam-break", "hydrostatic"}) {
    WcsphConfig config;
    config.scenario = name;
    config.resolution = 4;
    const SphScenario s = wcsph_scenario(config);
    const SphParameters& p = s.params;
    const TimeStepLimits lim =
        wcsph_time_step(p.smoothing_length, p.sound_speed, 0.1f * p.sound_speed,
                        100.0f * config.gravity, p.rest_density, p.viscosity);
    EXPECT_LE(p.dt, lim.cfl * (1 + 1e-6)) << name;
    EXPECT_LE(p.dt, lim.force) << name;
    EXPECT_LE(p.dt, lim.viscous) << name;
    // c0 = 10 x the largest expected speed: sqrt(2 g H) (hydrostatic), 2 sqrt(g H) (dam break).
    const float expected_speed = std::string(name) == "dam-break" ? 2.0f * std::sqrt(9.81f * 0.2f)
                                                                  : std::sqrt(2.0f * 9.81f * 0.2f);
    EXPECT_NEAR(p.sound_speed, 10.0f * expected_speed, 1e-3f);
  }
}

// On a lattice block with a linear pressure p = G (H - y), the force pass of the weakly
// compressible mode, divided by rho_i, gives -grad p / rho0 = (0, G / rho0, 0) at inner
// particles; the article's Mueller term gives half of it (why the mode doubles the mass).
TEST(SphValidation, ForcePassIsAConsistentPressureGradient) {
  WcsphConfig config;
  config.scenario = "hydrostatic";
  config.resolution = 4;
  const SphScenario base = wcsph_scenario(config);
  const SphParameters& params = base.params;
  const float dx = config.dx();
  const int side = 12;
  std::vector<float> x;
  for (int k = 0; k < side; ++k)
    for (int j = 0; j < side; ++j)
      for (int i = 0; i < side; ++i) {
        x.push_back((i + 0.5f) * dx);
        x.push_back((j + 0.5f) * dx);
        x.push_back((k + 0.5f) * dx);
      }
  const std::size_t n = x.size() / 3;
  const float g = 9.81f, rho0 = params.rest_density, height = side * dx;
  std::vector<float> v(3 * n, 0.0f), rho(n), p(n);
  Engine engine("cell-list");
  engine.build({x.data(), n, MemorySpace::host}, params.smoothing_length);
  KernelOptions density;
  density.sph_mass = params.particle_mass;
  engine.run(Kernel::sph_density, density);
  const std::vector<float> rho_sum = engine.results().density;
  const double self = params.particle_mass * 315.0 /
                      (64.0 * 3.14159265358979 * std::pow(double{params.smoothing_length}, 3));
  for (std::size_t i = 0; i < n; ++i) {
    rho[i] = rho0;
    p[i] = rho0 * g * (height - x[3 * i + 1]);
  }
  const auto inner = [&](std::size_t i) {
    const float reach = params.smoothing_length + 0.01f * dx;
    for (int a = 0; a < 3; ++a)
      if (x[3 * i + a] < reach || x[3 * i + a] > side * dx - reach) return false;
    return true;
  };
  for (const bool wcsph : {true, false}) {
    SphParameters prm = params;
    prm.weakly_compressible = wcsph;
    KernelOptions o = force_pass_options(prm);
    o.sph = {v.data(), rho.data(), p.data()};
    engine.run(Kernel::sph_force, o);
    const std::vector<float> f = engine.results().force;
    int checked = 0;
    for (std::size_t i = 0; i < n; ++i) {
      if (!inner(i)) continue;
      ++checked;
      // The lattice's inner density is rho0 (the calibrated mass).
      EXPECT_NEAR(rho_sum[i] + self, rho0, 1e-3 * rho0);
      const float expect = (wcsph ? 1.0f : 0.5f * 0.947f) * g;  // article: no renormalisation
      EXPECT_NEAR(f[3 * i + 1] / rho0, expect, (wcsph ? 1e-3f : 0.01f) * g) << i;
      EXPECT_NEAR(f[3 * i] / rho0, 0.0f, 1e-3f * g);
      EXPECT_NEAR(f[3 * i + 2] / rho0, 0.0f, 1e-3f * g);
    }
    EXPECT_GT(checked, 100);
  }
}

TEST(SphValidation, FixedParticlesNeverMove) {
  WcsphConfig config;
  config.scenario = "dam-break";
  config.resolution = 4;
  const SphScenario s = wcsph_scenario(config);
  ASSERT_EQ(s.fixed.size(), s.position.size() / 3);
  Solver solver(s, "cell-list");
  for (int i = 0; i < 60; ++i) solver.step();
  std::vector<float> x, v, rho, p;
  solver.copy_state(x, v, rho, p);
  std::size_t fixed = 0;
  float fluid_moved = 0;
  for (std::size_t i = 0; i < s.fixed.size(); ++i) {
    for (int a = 0; a < 3; ++a) {
      if (s.fixed[i] != 0.0f) {
        ASSERT_EQ(x[3 * i + a], s.position[3 * i + a]) << i;
        ASSERT_EQ(v[3 * i + a], 0.0f) << i;
      } else {
        fluid_moved = std::max(fluid_moved, std::abs(x[3 * i + a] - s.position[3 * i + a]));
      }
    }
    if (s.fixed[i] != 0.0f) ++fixed;
  }
  EXPECT_GT(fixed, 0u);
  EXPECT_GT(fluid_moved, 0.0f);  // the column does collapse
  // Boundary particles do get density and pressure (dynamic boundary conditions).
  float boundary_p = 0;
  for (std::size_t i = 0; i < s.fixed.size(); ++i)
    if (s.fixed[i] != 0.0f) boundary_p = std::max(boundary_p, p[i]);
  EXPECT_GT(boundary_p, 0.0f);
}

TEST(SphValidation, ScenarioFileAndKeys) {
  const auto path = std::filesystem::temp_directory_path() / "raycut_wcsph_test.cfg";
  {
    std::ofstream f(path);
    f << "# a test\nscenario = hydrostatic\nresolution = 6\n c0 = 30 \nviscosity_alpha=0.1\n"
         "negative_pressure = keep\nend_time = 0.01\n";
  }
  const WcsphConfig c = read_wcsph_config(path.string());
  EXPECT_EQ(c.scenario, "hydrostatic");
  EXPECT_EQ(c.resolution, 6);
  EXPECT_EQ(c.c0(), 30.0f);
  EXPECT_EQ(c.viscosity_alpha, 0.1f);
  EXPECT_FALSE(c.clamp_negative_pressure);
  EXPECT_EQ(c.run_time(), 0.01f);
  WcsphConfig d;
  set_wcsph_key(d, "dx", "0.005");
  EXPECT_EQ(d.resolution, 20);
  EXPECT_THROW(set_wcsph_key(d, "nonsense", "1"), Error);
  EXPECT_THROW(set_wcsph_key(d, "cfl", "abc"), Error);
  {
    std::ofstream f(path);
    f << "resolution 6\n";
  }
  EXPECT_THROW(read_wcsph_config(path.string()), Error);
  std::filesystem::remove(path);
}

// A tiny column (5 x 10 x 5 fluid particles) settles under gravity (damped for 0.1 s, then 0.05 s
// free) with pressure growing with depth at about rho0 g (fitted slope over the layers below the
// top two), density within 2 %.
TEST(SphValidation, TinyHydrostaticColumn) {
  WcsphConfig config;
  config.scenario = "hydrostatic";
  config.resolution = 5;
  config.column_width = 0.05f;  // dx = 0.01 m, H = 0.1 m
  config.damping_time = 0.1f;
  config.end_time = 0.15f;
  const SphScenario s = wcsph_scenario(config);
  Solver solver(s, "cell-list");
  for (int i = 0; i < s.frames; ++i) solver.step();
  std::vector<float> x, v, rho, p;
  solver.copy_state(x, v, rho, p);
  const double dx = config.dx(), rho0 = config.rest_density, g = config.gravity;
  const int layers = 10;
  // Least-squares slope of p against y over the fluid particles below the top two layers.
  double sy = 0, sp = 0, syy = 0, syp = 0, worst_rho = 0;
  int count = 0;
  for (std::size_t i = 0; i < s.fixed.size(); ++i) {
    if (s.fixed[i] != 0.0f) continue;
    const double y = x[3 * i + 1];
    if (y > (layers - 2) * dx) continue;
    sy += y;
    sp += p[i];
    syy += y * y;
    syp += y * p[i];
    worst_rho = std::max(worst_rho, std::abs(rho[i] / rho0 - 1.0));
    ++count;
  }
  ASSERT_GT(count, 100);
  const double slope = (count * syp - sy * sp) / (count * syy - sy * sy);
  std::printf("tiny column: dp/dy = %.1f Pa/m (-rho0 g = %.1f), max |rho/rho0 - 1| = %.3f %%\n",
              slope, -rho0 * g, 100 * worst_rho);
  EXPECT_NEAR(-slope / (rho0 * g), 1.0, 0.35);
  EXPECT_LT(worst_rho, 0.02);
}

}  // namespace
}  // namespace raycut::sph
