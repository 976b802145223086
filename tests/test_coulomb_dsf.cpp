// coulomb_dsf (damped shifted-force Coulomb, Fennell & Gezelter 2006) on every method that takes
// boxes, batches and query points (the CPU methods; brute-force-gpu and grid where a GPU is), on
// open, periodic (triclinic, thinner than 2C: several images and self-images), batched and
// query-point inputs, against a double-precision oracle written here from the paper's formulas:
// it shares no code with the library (its own image enumeration, erfc in double).
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "error_helpers.hpp"
#include "raycut/engine.hpp"
#include "raycut/tools/device_array.hpp"

namespace {

using raycut::Box;
using raycut::Engine;
using raycut::ErrorCode;
using raycut::Kernel;
using raycut::KernelOptions;
using raycut::MemorySpace;
using raycut::Systems;

constexpr double pi = 3.14159265358979323846;

// The action throws raycut::Error with `code`, its message holding `part`.
template <class Action>
void expect_error(Action&& action, ErrorCode code, const std::string& part) {
  const std::string message = raycut_test::error_message(code, action);
  EXPECT_TRUE(raycut_test::contains(message, part)) << message;
}

// ---- the oracle -------------------------------------------------------------------------------

struct Dsf {
  double alpha, cutoff, k;
  // phi(r) = erfc(a r) / r - erfc(a C) / C + (erfc(a C) / C^2 + 2a / sqrt(pi) exp(-a^2 C^2) / C)
  // (r - C), and its derivative.
  double slope_at_cutoff() const {
    const double c = cutoff, a = alpha;
    return std::erfc(a * c) / (c * c) + 2 * a / std::sqrt(pi) * std::exp(-a * a * c * c) / c;
  }
  double phi(double r) const {
    return std::erfc(alpha * r) / r - std::erfc(alpha * cutoff) / cutoff +
           slope_at_cutoff() * (r - cutoff);
  }
  double dphi(double r) const {
    return -std::erfc(alpha * r) / (r * r) -
           2 * alpha / std::sqrt(pi) * std::exp(-alpha * alpha * r * r) / r + slope_at_cutoff();
  }
  double self(double q) const {
    return -(std::erfc(alpha * cutoff) / (2 * cutoff) + alpha / std::sqrt(pi)) * k * q * q;
  }
};

// Per-target values and, per value, the sum of its terms' magnitudes (the scale of its float
// round-off).
struct Expected {
  std::vector<double> energy, force, virial;
  std::vector<double> energy_scale, force_scale, virial_scale;
  void resize(std::size_t n) {
    energy.assign(n, 0);
    energy_scale.assign(n, 0);
    force.assign(3 * n, 0);
    force_scale.assign(3 * n, 0);
    virial.assign(6 * n, 0);
    virial_scale.assign(6 * n, 0);
  }
};

struct Cell {
  double rows[3][3] = {};
  bool pbc[3] = {};
};

// Images per periodic axis: enough that every image within C of a point in the cell is seen
// (positions are generated inside it).
std::array<int, 3> image_reach(const Cell& cell, double cutoff) {
  std::array<int, 3> reach{0, 0, 0};
  const auto& c = cell.rows;
  const double volume = std::fabs(c[0][0] * (c[1][1] * c[2][2] - c[1][2] * c[2][1]) -
                                  c[0][1] * (c[1][0] * c[2][2] - c[1][2] * c[2][0]) +
                                  c[0][2] * (c[1][0] * c[2][1] - c[1][1] * c[2][0]));
  for (int a = 0; a < 3; ++a) {
    if (!cell.pbc[a]) continue;
    const double* u = c[(a + 1) % 3];
    const double* v = c[(a + 2) % 3];
    const double cross[3] = {u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2],
                             u[0] * v[1] - u[1] * v[0]};
    const double width =
        volume / std::sqrt(cross[0] * cross[0] + cross[1] * cross[1] + cross[2] * cross[2]);
    reach[a] = static_cast<int>(std::ceil(cutoff / width)) + 1;
  }
  return reach;
}

// Adds to `out` (rows first..first + targets) the DSF sums of the targets over the sources and
// their images. same_set: the targets are the sources (no (i, i, 0) pair).
void oracle(const Dsf& dsf, const Cell& cell, const std::vector<double>& targets,
            const std::vector<double>& target_charge, const std::vector<double>& sources,
            const std::vector<double>& source_charge, bool same_set, Expected& out,
            std::size_t first) {
  const std::array<int, 3> reach = image_reach(cell, dsf.cutoff);
  const std::size_t nt = target_charge.size(), ns = source_charge.size();
  for (std::size_t i = 0; i < nt; ++i) {
    const std::size_t row = first + i;
    const double qi = target_charge[i];
    out.energy[row] += dsf.self(qi);
    out.energy_scale[row] += std::fabs(dsf.self(qi));
    for (std::size_t j = 0; j < ns; ++j)
      for (int sa = -reach[0]; sa <= reach[0]; ++sa)
        for (int sb = -reach[1]; sb <= reach[1]; ++sb)
          for (int sc = -reach[2]; sc <= reach[2]; ++sc) {
            if (same_set && i == j && sa == 0 && sb == 0 && sc == 0) continue;
            double d[3];
            for (int k = 0; k < 3; ++k)
              d[k] = sources[3 * j + k] - targets[3 * i + k] + sa * cell.rows[0][k] +
                     sb * cell.rows[1][k] + sc * cell.rows[2][k];
            const double r = std::sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
            if (!(r < dsf.cutoff)) continue;
            const double kqq = dsf.k * qi * source_charge[j];
            const double e = 0.5 * kqq * dsf.phi(r);
            out.energy[row] += e;
            out.energy_scale[row] += std::fabs(kqq) * (std::erfc(dsf.alpha * r) / r + 1 / r);
            const double g = kqq * dsf.dphi(r) / r;  // force on the target: g d
            const double f[3] = {g * d[0], g * d[1], g * d[2]};
            const int a[6] = {0, 1, 2, 0, 0, 1}, b[6] = {0, 1, 2, 1, 2, 2};
            for (int k = 0; k < 3; ++k) {
              out.force[3 * row + k] += f[k];
              out.force_scale[3 * row + k] += std::fabs(f[k]) + std::fabs(kqq) / (r * r);
            }
            for (int k = 0; k < 6; ++k) {
              out.virial[6 * row + k] += -0.5 * d[a[k]] * f[b[k]];
              out.virial_scale[6 * row + k] += std::fabs(d[a[k]] * f[b[k]]) + std::fabs(kqq) / r;
            }
          }
  }
}

// ---- inputs -----------------------------------------------------------------------------------

struct Points {
  std::vector<float> xyz;     // what the engine gets
  std::vector<double> xyz64;  // the same values, for the oracle
  std::vector<float> charge;  // the engine's
  std::vector<double> charge64;
};

// n points inside the cell (fractional coordinates in [0, 1) along periodic axes, the cell's
// extent along open ones), charges in [-1, 1].
Points make_points(std::size_t n, const Cell& cell, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0), charge(-1.0, 1.0);
  Points p;
  for (std::size_t i = 0; i < n; ++i) {
    const double s[3] = {unit(rng), unit(rng), unit(rng)};
    for (int k = 0; k < 3; ++k) {
      const double x = s[0] * cell.rows[0][k] + s[1] * cell.rows[1][k] + s[2] * cell.rows[2][k];
      p.xyz.push_back(static_cast<float>(x));
      p.xyz64.push_back(static_cast<double>(p.xyz.back()));
    }
    p.charge.push_back(static_cast<float>(charge(rng)));
    p.charge64.push_back(p.charge.back());
  }
  return p;
}

Box box_of(const Cell& cell) {
  Box box;
  for (int a = 0; a < 3; ++a) {
    box.pbc[a] = cell.pbc[a];
    for (int k = 0; k < 3; ++k) box.cell[a][k] = cell.rows[a][k];
  }
  return box;
}

Cell cube(double l, bool periodic) {
  Cell c;
  for (int a = 0; a < 3; ++a) {
    c.rows[a][a] = l;
    c.pbc[a] = periodic;
  }
  return c;
}

// Triclinic, thinner than 2 C along c: pairs meet several images of a source and themselves.
Cell triclinic() {
  Cell c;
  const double rows[3][3] = {{3.1, 0, 0}, {0.9, 2.8, 0}, {-0.6, 0.7, 1.9}};
  for (int a = 0; a < 3; ++a) {
    c.pbc[a] = true;
    for (int k = 0; k < 3; ++k) c.rows[a][k] = rows[a][k];
  }
  return c;
}

void expect_matches(const raycut::Results& got, const Expected& want, const std::string& what) {
  const std::size_t n = want.energy.size();
  ASSERT_EQ(got.energy.size(), n) << what;
  ASSERT_EQ(got.force.size(), 3 * n) << what;
  ASSERT_EQ(got.virial.size(), 6 * n) << what;
  auto near = [&](float g, double w, double scale, const char* name, std::size_t index) {
    EXPECT_NEAR(g, w, 2e-5 * scale + 1e-12) << what << ": " << name << "[" << index << "]";
  };
  for (std::size_t i = 0; i < n; ++i)
    near(got.energy[i], want.energy[i], want.energy_scale[i], "energy", i);
  for (std::size_t i = 0; i < 3 * n; ++i)
    near(got.force[i], want.force[i], want.force_scale[i], "force", i);
  for (std::size_t i = 0; i < 6 * n; ++i)
    near(got.virial[i], want.virial[i], want.virial_scale[i], "virial", i);
}

// `values` where `engine` reads its inputs: in place on the host, a device copy (kept in
// `holder`) for a method that works on the device.
const float* where_read(const Engine& engine, const std::vector<float>& values,
                        std::optional<raycut::DeviceArray>& holder) {
  if (engine.space() == MemorySpace::host) return values.data();
  holder.emplace(values);
  return holder->data();
}

// Why `method` cannot run here; empty when it can.
std::string unavailable(const std::string& method) {
  for (const auto& m : raycut::list_methods())
    if (m.name == method)
      return m.available ? "" : (m.why_unavailable.empty() ? "not available" : m.why_unavailable);
  return "not in list_methods()";
}

struct DsfRun {
  KernelOptions options;
  std::optional<raycut::DeviceArray> charge, query_charge;
};

// The options of a run of `dsf` over charges p on `engine` (which must be built).
void set_options(DsfRun& run, const Engine& engine, const Dsf& dsf, const Points& p) {
  run.options.dsf_alpha = static_cast<float>(dsf.alpha);
  run.options.coulomb_constant = static_cast<float>(dsf.k);
  run.options.coulomb.charge = where_read(engine, p.charge, run.charge);
}

// The oracle's constants from the float values the engine gets.
Dsf dsf_of(float alpha, float cutoff, float k) {
  return {alpha, std::sqrt(static_cast<double>(static_cast<float>(double{cutoff} * cutoff))), k};
}

class CoulombDsf : public ::testing::TestWithParam<const char*> {
 protected:
  void SetUp() override {
    const std::string why = unavailable(GetParam());
    if (!why.empty()) GTEST_SKIP() << GetParam() << ": " << why;
  }
};

TEST_P(CoulombDsf, OpenCloudMatchesTheOracle) {
  const float cutoff = 2.5f;
  for (float alpha : {0.0f, 0.35f, 1.2f}) {
    const Dsf dsf = dsf_of(alpha, cutoff, 14.399645f);
    const Cell open = cube(8.0, false);
    const Points p = make_points(300, open, 7);
    Engine engine(GetParam());
    engine.build({p.xyz.data(), 300, MemorySpace::host}, cutoff);
    DsfRun run;
    set_options(run, engine, dsf, p);
    const raycut::Results got = engine.compute(Kernel::coulomb_dsf, run.options);
    Expected want;
    want.resize(300);
    oracle(dsf, Cell{}, p.xyz64, p.charge64, p.xyz64, p.charge64, true, want, 0);
    expect_matches(got, want, "open, alpha " + std::to_string(alpha));
    // Newton's third law: the forces add up to 0.
    for (int k = 0; k < 3; ++k) {
      double total = 0, scale = 0;
      for (std::size_t i = 0; i < 300; ++i) {
        total += got.force[3 * i + k];
        scale += want.force_scale[3 * i + k];
      }
      EXPECT_NEAR(total, 0.0, 1e-5 * scale);
    }
  }
}

TEST_P(CoulombDsf, PeriodicTriclinicWithSelfImagesMatchesTheOracle) {
  const Cell cell = triclinic();
  const float cutoff = 2.2f;  // > the c-axis width: every particle sees its own images
  const Dsf dsf = dsf_of(0.4f, cutoff, 1.0f);
  const Points p = make_points(40, cell, 11);
  Engine engine(GetParam());
  Systems systems;
  systems.box = box_of(cell);
  engine.build({p.xyz.data(), 40, MemorySpace::host}, cutoff, systems);
  DsfRun run;
  set_options(run, engine, dsf, p);
  const raycut::Results got = engine.compute(Kernel::coulomb_dsf, run.options);
  Expected want;
  want.resize(40);
  oracle(dsf, cell, p.xyz64, p.charge64, p.xyz64, p.charge64, true, want, 0);
  expect_matches(got, want, "triclinic");
}

TEST_P(CoulombDsf, BatchedSystemsMatchTheOracleSystemBySystem) {
  const float cutoff = 2.0f;
  const Dsf dsf = dsf_of(0.5f, cutoff, 2.0f);
  const Cell cells[3] = {cube(4.5, true), triclinic(), cube(6.0, false)};
  const std::size_t sizes[3] = {50, 30, 60};
  Points all;
  Systems systems;
  systems.offsets.push_back(0);
  std::vector<Points> parts;
  for (int s = 0; s < 3; ++s) {
    parts.push_back(make_points(sizes[s], cells[s], 20 + s));
    const Points& p = parts.back();
    all.xyz.insert(all.xyz.end(), p.xyz.begin(), p.xyz.end());
    all.charge.insert(all.charge.end(), p.charge.begin(), p.charge.end());
    systems.offsets.push_back(systems.offsets.back() + sizes[s]);
    Box box = box_of(cells[s]);
    if (!cells[s].pbc[0]) box = Box::open();
    systems.boxes.push_back(box);
  }
  const std::size_t n = systems.offsets.back();
  Engine engine(GetParam());
  engine.build({all.xyz.data(), n, MemorySpace::host}, cutoff, systems);
  DsfRun run;
  set_options(run, engine, dsf, all);
  const raycut::Results got = engine.compute(Kernel::coulomb_dsf, run.options);
  Expected want;
  want.resize(n);
  for (int s = 0; s < 3; ++s) {
    const Points& p = parts[s];
    oracle(dsf, cells[s].pbc[0] ? cells[s] : Cell{}, p.xyz64, p.charge64, p.xyz64, p.charge64, true,
           want, systems.offsets[s]);
  }
  expect_matches(got, want, "batch");
}

TEST_P(CoulombDsf, QueryPointsReadTheirOwnCharges) {
  const float cutoff = 2.4f;
  const Dsf dsf = dsf_of(0.3f, cutoff, 1.0f);
  for (bool periodic : {false, true}) {
    const Cell cell = cube(5.0, periodic);
    const Points sources = make_points(120, cell, 3);
    const Points queries = make_points(25, cell, 4);
    Systems systems;
    if (periodic) systems.box = box_of(cell);
    systems.queries = {queries.xyz.data(), 25, MemorySpace::host};
    Engine engine(GetParam());
    engine.build({sources.xyz.data(), 120, MemorySpace::host}, cutoff, systems);
    DsfRun run;
    set_options(run, engine, dsf, sources);
    KernelOptions& o = run.options;
    o.coulomb.query_charge = where_read(engine, queries.charge, run.query_charge);
    const raycut::Results got = engine.compute(Kernel::coulomb_dsf, o);
    Expected want;
    want.resize(25);
    oracle(dsf, periodic ? cell : Cell{}, queries.xyz64, queries.charge64, sources.xyz64,
           sources.charge64, false, want, 0);
    expect_matches(got, want, periodic ? "periodic queries" : "open queries");

    // Query charges are required with query points.
    o.coulomb.query_charge = nullptr;
    expect_error([&] { engine.compute(Kernel::coulomb_dsf, o); }, ErrorCode::invalid_argument,
                 "query_charge is missing");
  }
}

INSTANTIATE_TEST_SUITE_P(SystemMethods, CoulombDsf,
                         ::testing::Values("brute-force", "cell-list", "brute-force-gpu", "grid"),
                         [](const auto& info) {
                           std::string name = info.param;
                           std::replace(name.begin(), name.end(), '-', '_');
                           return name;
                         });

// The oracle itself: its force is minus the gradient of its energy (central differences in
// double), its pair energy and force vanish at the cutoff, and with alpha = 0 the self term is
// -k q^2 / (2 C).
TEST(CoulombDsfOracle, ForceIsMinusTheEnergyGradientAndVanishesAtTheCutoff) {
  const Dsf dsf{0.45, 2.5, 1.7};
  EXPECT_NEAR(dsf.phi(dsf.cutoff), 0.0, 1e-15);
  EXPECT_NEAR(dsf.dphi(dsf.cutoff), 0.0, 1e-15);
  EXPECT_DOUBLE_EQ(Dsf({0.0, 2.0, 3.0}).self(0.5), -3.0 * 0.25 / 4.0);
  const Points p = make_points(12, cube(3.0, false), 5);
  auto total_energy = [&](const std::vector<double>& xyz) {
    Expected e;
    e.resize(12);
    oracle(dsf, Cell{}, xyz, p.charge64, xyz, p.charge64, true, e, 0);
    double sum = 0;
    for (double v : e.energy) sum += v;
    return sum;
  };
  Expected e;
  e.resize(12);
  oracle(dsf, Cell{}, p.xyz64, p.charge64, p.xyz64, p.charge64, true, e, 0);
  const double h = 1e-6;
  for (std::size_t c = 0; c < 36; ++c) {
    std::vector<double> plus = p.xyz64, minus = p.xyz64;
    plus[c] += h;
    minus[c] -= h;
    const double gradient = (total_energy(plus) - total_energy(minus)) / (2 * h);
    EXPECT_NEAR(e.force[c], -gradient, 1e-6 * (1 + std::fabs(gradient))) << "coordinate " << c;
  }
}

// The kernel's own numbers: two charges just inside the cutoff feel (almost) nothing; the self
// term alone is the energy of an isolated charge.
TEST(CoulombDsfKernel, VanishesAtTheCutoffAndKeepsTheSelfTerm) {
  const float cutoff = 3.0f, alpha = 0.25f;
  const float xyz[6] = {0, 0, 0, 2.9999f, 0, 0};
  const float charge[2] = {1.0f, -2.0f};
  KernelOptions o;
  o.dsf_alpha = alpha;
  o.coulomb.charge = charge;
  Engine engine("brute-force");
  engine.build({xyz, 2, MemorySpace::host}, cutoff);
  const raycut::Results r = engine.compute(Kernel::coulomb_dsf, o);
  const Dsf dsf = dsf_of(alpha, cutoff, 1.0f);
  // The force on 0 along x, k q0 q1 phi'(r), is O(C - r): ~1e-5 here, 1e-4 of its value at C / 2.
  const double r01 = static_cast<double>(xyz[3]);
  EXPECT_NEAR(r.force[0], -2.0 * dsf.dphi(r01), 1e-7);
  EXPECT_LT(std::fabs(r.force[0]), 1e-4 * std::fabs(2.0 * dsf.dphi(0.5 * cutoff)));
  EXPECT_NEAR(r.energy[0], dsf.self(1.0), 1e-6);
  EXPECT_NEAR(r.energy[1], dsf.self(-2.0), 1e-6);
  // Far apart: only the self terms.
  const float far[6] = {0, 0, 0, 10, 0, 0};
  engine.build({far, 2, MemorySpace::host}, cutoff);
  const raycut::Results alone = engine.compute(Kernel::coulomb_dsf, o);
  EXPECT_FLOAT_EQ(alone.energy[1], static_cast<float>(dsf.self(-2.0)));
  EXPECT_EQ(alone.force[3], 0.0f);
}

TEST(CoulombDsfKernel, RefusesBadParametersAndMissingInputs) {
  const float xyz[6] = {0, 0, 0, 1, 0, 0};
  const float charge[2] = {1, 1};
  Engine engine("cell-list");
  engine.build({xyz, 2, MemorySpace::host}, 2.0f);
  KernelOptions o;
  expect_error([&] { engine.compute(Kernel::coulomb_dsf, o); }, ErrorCode::invalid_argument,
               "charge is missing");
  o.coulomb.charge = charge;
  o.dsf_alpha = -0.5f;
  expect_error([&] { engine.compute(Kernel::coulomb_dsf, o); }, ErrorCode::invalid_argument,
               "parameter alpha = -0.5 is not accepted (finite values in [0, inf])");
  o.dsf_alpha = NAN;
  expect_error([&] { engine.compute(Kernel::coulomb_dsf, o); }, ErrorCode::invalid_argument,
               "parameter alpha = nan");
  o.dsf_alpha = 0.5f;
  o.coulomb_constant = INFINITY;
  expect_error([&] { engine.compute(Kernel::coulomb_dsf, o); }, ErrorCode::invalid_argument,
               "coulomb_constant = inf");
  o.coulomb_constant = 1.0f;
  o.coulomb.query_charge = charge;
  expect_error([&] { engine.compute(Kernel::coulomb_dsf, o); }, ErrorCode::invalid_argument,
               "query_charge is given without query points");
  o.coulomb.query_charge = nullptr;
  o.dsf_alpha = 1e30f;  // (alpha C)^2 overflows float
  expect_error([&] { engine.compute(Kernel::coulomb_dsf, o); }, ErrorCode::invalid_argument,
               "alpha^2 C^2");
  EXPECT_EQ(raycut::parse_kernel("coulomb_dsf"), Kernel::coulomb_dsf);
  EXPECT_EQ(raycut::to_string(Kernel::coulomb_dsf), "coulomb_dsf");
}

// The catalogue's dispatches agree with one another for every kernel.
TEST(KernelCatalogue, NamesRoundTripAndOutputsMatchTheResults) {
  raycut::for_each_kernel([](auto spec) {
    using Spec = decltype(spec);
    EXPECT_EQ(raycut::parse_kernel(Spec::name), Spec::id);
    EXPECT_EQ(raycut::to_string(Spec::id), Spec::name);
    const raycut::KernelProduces p = raycut::produces(Spec::id);
    EXPECT_EQ(p.energy, Spec::outputs.energy);
    EXPECT_EQ(p.force, Spec::outputs.force);
  });
  static_assert(raycut::produces(Kernel::coulomb_dsf).virial);
  static_assert(!raycut::produces(Kernel::coulomb_dsf).count);
}

}  // namespace
