// The supported domain (docs/limits.md): cutoff range, kernel output range, NaN-aware result
// comparison, the CPU methods' N bound, and the cell list's immunity to far outliers.
#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "core/method.hpp"
#include "core/validation.hpp"
#include "raycut/engine.hpp"
#include "raycut/sph/scenario.hpp"
#include "raycut/sph/solver.hpp"
#include "raycut/tools/compare.hpp"
#include "raycut/tools/generators.hpp"

namespace {

using raycut::Engine;
using raycut::Error;
using raycut::ErrorCode;
using raycut::Kernel;
using raycut::KernelOptions;
using raycut::MemorySpace;

// Runs f, expecting Error(invalid_argument) whose message contains `needle`.
template <class F>
void expect_invalid(F&& f, const std::string& needle) {
  try {
    f();
    ADD_FAILURE() << "no error thrown (expected one mentioning '" << needle << "')";
  } catch (const Error& e) {
    EXPECT_EQ(e.code(), ErrorCode::invalid_argument) << e.what();
    EXPECT_NE(std::string(e.what()).find(needle), std::string::npos) << e.what();
  }
}

TEST(CutoffRange, EdgesAcceptedOutsideRefusedWithTheRangeNamed) {
  using raycut::detail::validate_cutoff;
  EXPECT_NO_THROW(validate_cutoff(0x1p-60f));
  EXPECT_NO_THROW(validate_cutoff(0x1p60f));
  EXPECT_NO_THROW(validate_cutoff(1.0f));
  for (float c : {std::nextafter(0x1p-60f, 0.0f), std::nextafter(0x1p60f, 1e30f), 1e-30f, 1e20f,
                  std::numeric_limits<float>::denorm_min(), std::numeric_limits<float>::max()}) {
    expect_invalid([&] { validate_cutoff(c); }, "[2^-60, 2^60]");
  }
  for (float c : {0.0f, -1.0f, std::numeric_limits<float>::infinity(),
                  std::numeric_limits<float>::quiet_NaN()}) {
    expect_invalid([&] { validate_cutoff(c); }, "finite and > 0");
  }
}

// Two inputs that used to give silently wrong answers are refused by Engine::build.
TEST(CutoffRange, EngineRefusesWhatUsedToBeSilentlyWrong) {
  const std::vector<float> coincident = {0, 0, 0, 0, 0, 0};
  const std::vector<float> far_pair = {0, 0, 0, 2e19f, 0, 0};
  Engine engine("brute-force");
  expect_invalid(
      [&] {
        engine.build({coincident.data(), 2, MemorySpace::host}, 1e-30f);
      },
      "supported range");
  expect_invalid(
      [&] {
        engine.build({far_pair.data(), 2, MemorySpace::host}, 1e20f);
      },
      "supported range");
  // At the edges of the range the answers are right: coincident points are pairs at the
  // smallest cutoff; a pair at 0.5 C is found at the largest; one at 2 C is not.
  for (float c : {0x1p-60f, 0x1p60f}) {
    const std::vector<float> xyz = {0, 0, 0, 0, 0, 0, 0.5f * c, 0, 0, 2 * c, 0, 0};
    for (const char* method : {"brute-force", "cell-list"}) {
      Engine e(method);
      e.build({xyz.data(), 4, MemorySpace::host}, c);
      const auto count = e.compute(Kernel::count).count;
      EXPECT_EQ(count, (std::vector<std::uint32_t>{2, 2, 2, 0})) << method << " C=" << c;
    }
  }
}

// Per-kernel: where validate_kernel_range accepts a cutoff, the kernel's terms on two points
// (coincident, and 0.5 C apart) are finite; where the float results are not finite, it refuses.
TEST(KernelRange, AgreesWithTheKernelsOverTheWholeCutoffRange) {
  const float velocity[9] = {0, 0, 0, 1, -1, 0.5f, 0, 0, 0};
  const float density[3] = {1, 1, 1};
  const float pressure[3] = {1, 1, 1};
  KernelOptions options;
  options.sph_mass = 1.0f;
  options.sph_viscosity = 1.0f;
  options.sph = {velocity, density, pressure};
  int accepted = 0, refused = 0;
  for (int e = -60; e <= 60; ++e) {
    const float c = std::ldexp(1.0f, e);
    const std::vector<float> xyz = {0, 0, 0, 0, 0, 0, 0.5f * c, 0, 0};
    Engine engine("brute-force");
    engine.build({xyz.data(), 3, MemorySpace::host}, c);
    for (Kernel k : {Kernel::smooth, Kernel::sph_density, Kernel::sph_force, Kernel::lj}) {
      bool ok = true;
      try {
        raycut::validate_kernel_range(k, options, c);
      } catch (const Error& err) {
        ok = false;
        EXPECT_EQ(err.code(), ErrorCode::invalid_argument);
        EXPECT_NE(std::string(err.what()).find(raycut::to_string(k)), std::string::npos);
      }
      (ok ? accepted : refused)++;
      if (!ok) {
        EXPECT_THROW(engine.compute(k, options), Error) << "C=" << c;
      }
      // The kernel's own terms, evaluated by its functor on the three points.
      std::vector<std::uint32_t> count(3);
      std::vector<float> energy(3), force(9), virial(18), rho(3);
      const raycut::KernelOutputs out{count.data(), energy.data(), force.data(), virial.data(),
                                      rho.data()};
      raycut::with_kernel(k, options, raycut::squared_cutoff(c), out, [&](const auto& f) {
        for (std::uint32_t i = 0; i < 3; ++i) {
          auto acc = raycut::initial_state(f, i);
          for (std::uint32_t j = 0; j < 3; ++j) {
            if (j == i) continue;
            const raycut::Vec3 r{xyz[3 * j] - xyz[3 * i], xyz[3 * j + 1] - xyz[3 * i + 1],
                                 xyz[3 * j + 2] - xyz[3 * i + 2]};
            const float r2 = raycut::squared_distance(r.x, r.y, r.z);
            if (raycut::in_range(r2, raycut::squared_cutoff(c))) raycut::apply(f, acc, i, j, r, r2);
          }
          f.finish(i, acc);
        }
      });
      bool finite = true;
      for (const auto* values : {&energy, &force, &rho})
        for (float v : *values) finite = finite && std::isfinite(v);
      const float first = k == Kernel::sph_density ? rho[0] : energy[0];
      if (k == Kernel::lj) {
        // Coincident points give r = 0: lj is infinite there by physics, never refused.
        EXPECT_TRUE(ok) << "C=" << c;
        continue;
      }
      EXPECT_TRUE(!ok || finite) << raycut::to_string(k) << " C=" << c << " accepted, not finite";
      // Accepted energies are not flushed to zero either.
      if (ok && k != Kernel::sph_force) {
        EXPECT_GT(first, 0.0f) << raycut::to_string(k) << " C=" << c;
      }
    }
  }
  EXPECT_GT(accepted, 0);
  EXPECT_GT(refused, 0);
}

TEST(KernelRange, TheReportedCases) {
  using raycut::validate_kernel_range;
  KernelOptions unit;
  unit.sph_mass = 1.0f;
  unit.sph_viscosity = 0.1f;
  expect_invalid([&] { validate_kernel_range(Kernel::smooth, {}, 1e10f); }, "overflows");
  expect_invalid([&] { validate_kernel_range(Kernel::smooth, {}, 1e-12f); }, "underflows");
  EXPECT_NO_THROW(validate_kernel_range(Kernel::smooth, {}, 1e9f));
  EXPECT_NO_THROW(validate_kernel_range(Kernel::smooth, {}, 1e-9f));
  expect_invalid([&] { validate_kernel_range(Kernel::sph_density, unit, 1e9f); }, "sph_density");
  expect_invalid([&] { validate_kernel_range(Kernel::sph_force, unit, 1e-7f); }, "sph_force");
  EXPECT_NO_THROW(validate_kernel_range(Kernel::sph_density, unit, 0.02f));
  EXPECT_NO_THROW(validate_kernel_range(Kernel::sph_force, unit, 0.02f));
  // A mass whose factor underflows to zero is refused; mass 0 is allowed (everything is 0).
  KernelOptions tiny = unit;
  tiny.sph_mass = 1e-40f;
  expect_invalid([&] { validate_kernel_range(Kernel::sph_density, tiny, 1e3f); }, "underflows");
  EXPECT_NO_THROW(validate_kernel_range(Kernel::sph_density, KernelOptions{}, 1e3f));
  // count and lj have no cutoff-dependent bound.
  for (float c : {0x1p-60f, 1.0f, 0x1p60f}) {
    EXPECT_NO_THROW(validate_kernel_range(Kernel::count, {}, c));
    EXPECT_NO_THROW(validate_kernel_range(Kernel::lj, {}, c));
  }
  KernelOptions huge_sigma;
  huge_sigma.lj_sigma = 1e7f;
  expect_invalid([&] { validate_kernel_range(Kernel::lj, huge_sigma, 1.0f); }, "sigma^6");
}

// lj_forces at the edges of the accepted sigma range (4 eps sigma^6 a normal float): two particles
// at 1.05 sigma, cutoff 2.5 sigma, against the double-precision force and virial. The raw factor
// r^-8 gave inf below sigma ~1e-5 and zero above ~3e5 (found by adversarial tests).
TEST(KernelRange, LjForcesAcrossTheSigmaRange) {
  for (const char* method : {"brute-force", "cell-list"})
    for (float sigma : {5e-7f, 1e-6f, 1e-5f, 1.0f, 3e5f, 1e6f, 2e6f}) {
      const float d = 1.05f * sigma;  // repulsive: 2u - 1 = 0.49, no cancellation
      const std::vector<float> xyz = {0, 0, 0, d, 0, 0};
      KernelOptions options;
      options.lj_sigma = sigma;
      options.lj_epsilon = 0.5f;
      Engine engine(method);
      engine.build({xyz.data(), 2, MemorySpace::host}, 2.5f * sigma);
      const raycut::Results r = engine.compute(Kernel::lj_forces, options);
      const double rr = d, q = std::pow(static_cast<double>(sigma) / rr, 6);
      const double energy = 0.5 * 4.0 * 0.5 * q * (q - 1.0);  // half the pair's, on each atom
      // Force on particle 0 along x: -dU/dx_0 = -24 eps u (2u - 1) / r^2 * (x_1 - x_0).
      const double force = -24.0 * 0.5 * q * (2.0 * q - 1.0) / (rr * rr) * rr;
      const double virial = 12.0 * 0.5 * q * (2.0 * q - 1.0) / (rr * rr) * rr * rr;
      const auto near = [](double got, double want) {
        return std::abs(got - want) <= 1e-5 * std::abs(want);
      };
      EXPECT_TRUE(near(r.energy[0], energy)) << method << " sigma " << sigma << ": " << r.energy[0];
      EXPECT_TRUE(near(r.force[0], force)) << method << " sigma " << sigma << ": " << r.force[0];
      EXPECT_TRUE(near(r.force[3], -force)) << method << " sigma " << sigma << ": " << r.force[3];
      EXPECT_TRUE(near(r.virial[0], virial)) << method << " sigma " << sigma << ": " << r.virial[0];
    }
}

// The SPH solver's own scenarios stay inside the kernels' range (Engine::run will refuse what
// validate_kernel_range refuses).
TEST(KernelRange, TheSphScenariosAreInRange) {
  using raycut::validate_kernel_range;
  for (const auto& scenario :
       {raycut::sph::hiprt_drop(), raycut::sph::small_drop(), raycut::sph::wcsph_scenario({})}) {
    const auto& p = scenario.params;
    KernelOptions density;
    density.sph_mass = p.particle_mass;
    density.sph_viscosity = p.viscosity;
    EXPECT_NO_THROW(validate_kernel_range(Kernel::sph_density, density, p.smoothing_length))
        << scenario.name;
    EXPECT_NO_THROW(validate_kernel_range(Kernel::sph_force, raycut::sph::force_pass_options(p),
                                          p.smoothing_length))
        << scenario.name;
  }
}

// 2^32 particles do not fit 32-bit indices: refused before the positions are read.
TEST(CpuMethods, RefuseTwoToThe32Particles) {
  const float dummy[3] = {0, 0, 0};
  for (auto* make : {&raycut::detail::make_cell_list_cpu, &raycut::detail::make_brute_force_cpu}) {
    auto method = make();
    expect_invalid([&] { method->build(dummy, std::size_t{1} << 32, 1.0f); }, "2^32");
  }
}

// One particle 1e9 cutoffs away used to widen every cell of the list (dimensions capped at 2^21
// per axis), making it O(N^2): counting 100k uniform points took 10-17 s with the outlier,
// 0.01 s without. Now the outlier costs nothing: same pairs, and a bound 100x above the fixed time.
TEST(CellList, FarOutlierCostsNothing) {
  const std::size_t n = 200000;
  for (float far : {1e9f, -3e38f}) {
    raycut::PointCloud cloud = raycut::make_family("uniform", n, 1.0f, 3);
    std::vector<std::uint32_t> plain;
    {
      Engine e("cell-list");
      e.build({cloud.xyz.data(), n, MemorySpace::host}, 1.0f);
      plain = e.compute(Kernel::count).count;
    }
    cloud.xyz.insert(cloud.xyz.end(), {far, far, 0.5f});
    const auto start = std::chrono::steady_clock::now();
    Engine e("cell-list");
    e.build({cloud.xyz.data(), n + 1, MemorySpace::host}, 1.0f);
    auto count = e.compute(Kernel::count).count;
    const double seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    ASSERT_EQ(count.size(), n + 1);
    EXPECT_EQ(count.back(), 0u);
    count.pop_back();
    EXPECT_EQ(count, plain) << "outlier at " << far;
    EXPECT_LT(seconds, 30.0) << "outlier at " << far << ": the cell list degraded to O(N^2)";
    RecordProperty("seconds_with_outlier_" + std::to_string(static_cast<int>(far > 0)),
                   std::to_string(seconds));
  }
}

TEST(CompareValues, NaNAndOneSidedInfinityAreMismatches) {
  constexpr float inf = std::numeric_limits<float>::infinity();
  constexpr float nan = std::numeric_limits<float>::quiet_NaN();
  using raycut::max_scaled_difference;
  using raycut::scaled_difference;
  EXPECT_DOUBLE_EQ(scaled_difference(1.5, 1.0, 2.0), 0.25);
  EXPECT_EQ(scaled_difference(nan, 1.0, 1.0), HUGE_VAL);
  EXPECT_EQ(scaled_difference(1.0, nan, 1.0), HUGE_VAL);
  EXPECT_EQ(scaled_difference(nan, nan, 1.0), HUGE_VAL);
  EXPECT_EQ(scaled_difference(inf, 1.0, 1.0), HUGE_VAL);
  EXPECT_EQ(scaled_difference(1.0, -inf, 1.0), HUGE_VAL);
  EXPECT_EQ(scaled_difference(inf, -inf, 1.0), HUGE_VAL);
  EXPECT_EQ(scaled_difference(inf, inf, 1.0), 0.0);
  EXPECT_EQ(scaled_difference(1.0, 2.0, 0.0), HUGE_VAL);
  const std::vector<double> unit(3, 1.0);
  // A NaN after a larger finite error, or first: either way the result is a failure (what
  // std::max(worst, NaN) used to swallow).
  EXPECT_EQ(max_scaled_difference({1, 5, nan}, {1, 1, 1}, unit), HUGE_VAL);
  EXPECT_EQ(max_scaled_difference({nan, 5, 1}, {1, 1, 1}, unit), HUGE_VAL);
  EXPECT_EQ(max_scaled_difference({1, 1, 1}, {1, inf, 1}, unit), HUGE_VAL);
  EXPECT_DOUBLE_EQ(max_scaled_difference({1, 3, 1}, {1, 1, 1}, unit), 2.0);
  EXPECT_EQ(max_scaled_difference({1, 1}, {1, 1, 1}, unit), HUGE_VAL);
  EXPECT_EQ(max_scaled_difference({}, {}, {}), 0.0);
  // Stride: one scale per 3 force components.
  EXPECT_DOUBLE_EQ(max_scaled_difference({0, 0, 4, 0, 0, 0}, {0, 0, 0, 0, 0, 0}, {2.0, 1.0}, 3),
                   2.0);
}

// `raycut check`'s smooth tolerance grows with the terms: 3,000 coincident particles far from
// the origin (at x = 1e5), C = 0.9: each target sums 2,999 equal terms w^2 (not a power of two),
// whose float sum is 3e-5 off the double one (more than the 1e-5 relative the check used to
// allow, which flagged exact results) and within the float summation bound. An error of 1e-3 of
// one target's sum (a wrong term, say) is still caught; a single term out of 3,000 near-equal
// ones is within what float summation may lose, and is the list comparison's to catch (pairs
// are compared exactly).
TEST(CompareValues, SmoothBoundGrowsWithTheTermsAndStillCatchesAnError) {
  const std::size_t n = 3000;
  std::vector<float> xyz(3 * n, 0.0f);
  for (std::size_t i = 0; i < n; ++i) xyz[3 * i] = 1e5f;
  raycut::Engine engine("cell-list");
  engine.build({xyz.data(), n, raycut::MemorySpace::host}, 0.9f);
  const raycut::NeighbourList list = engine.neighbours();
  ASSERT_EQ(list.indices.size(), n * (n - 1));
  const raycut::SmoothReference ref = raycut::smooth_reference(xyz.data(), 0.9f, list);
  raycut::Results got = engine.compute(raycut::Kernel::smooth);
  double old_relative = 0;  // the former criterion: |e - e_ref| / (count C^4)
  for (std::size_t i = 0; i < n; ++i)
    old_relative = std::max(
        old_relative, std::fabs(got.energy[i] - ref.energy[i]) / ((n - 1) * std::pow(0.9, 4)));
  EXPECT_GT(old_relative, 1e-5) << "the case no longer shows the float sum's error";
  EXPECT_LE(raycut::smooth_bound_ratio(got, ref), 1.0);
  got.energy[17] *= 1.001f;
  EXPECT_GT(raycut::smooth_bound_ratio(got, ref), 1.0);
}

}  // namespace
