// A caller's own pair functor through raycut::for_each_pair on the CPU methods: functors with the
// built-in Lennard-Jones math give the built-in results bit for bit; init() without combine();
// N = 0 and 1; the forces and virial of Kernel::lj_forces against double-precision references
// (finite differences of the total energy, pair sums); GPU methods refuse.
#include <gtest/gtest.h>

#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <numeric>
#include <string>
#include <vector>

#if defined(_OPENMP)
#include <omp.h>
#endif

#include "raycut/engine.hpp"
#include "raycut/pairs.hpp"
#include "raycut/tools/generators.hpp"
#include "user_functors.hpp"

// tests/pairs_without_engine.cpp: for_each_pair compiled with <raycut/pairs.hpp> alone.
std::vector<std::uint32_t> neighbour_counts_through_pairs_header(const raycut::Engine& engine,
                                                                 std::size_t size);

namespace {

using raycut::Engine;
using raycut::Kernel;
using raycut::MemorySpace;

const char* const cpu_methods[] = {"brute-force", "cell-list"};
const char* const families[] = {
    "uniform",         "sphere-surface", "lattice-k2",       "lattice-shifted-k3",
    "near-coincident", "axis-aligned",   "gaussian-outlier", "offset-1e3"};

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

// The first index where a and b differ in bits, for the failure message.
std::string first_difference(const std::vector<float>& a, const std::vector<float>& b) {
  if (a.size() != b.size())
    return "sizes " + std::to_string(a.size()) + " and " + std::to_string(b.size());
  for (std::size_t k = 0; k < a.size(); ++k)
    if (std::memcmp(&a[k], &b[k], sizeof(float)) != 0)
      return "index " + std::to_string(k) + ": " + std::to_string(a[k]) + " vs " +
             std::to_string(b[k]);
  return "none";
}

template <class Body>
void for_each_case(Body&& body) {
  raycut::KernelOptions options;
  options.lj_epsilon = 1.5f;
  options.lj_sigma = 0.35f;  // not the defaults: the parameters matter
  for (const char* method : cpu_methods)
    for (const char* family : families)
      for (std::size_t n : {2u, 257u, 3000u}) {
        const float cutoff = 0.5f;
        const raycut::PointCloud cloud = raycut::make_family(family, n, cutoff, 7 + n);
        SCOPED_TRACE(std::string(method) + " " + family + " n=" + std::to_string(cloud.size()));
        Engine engine(method);
        engine.build({cloud.xyz.data(), cloud.size(), MemorySpace::host}, cutoff);
        body(engine, options);
      }
}

// (a) A user functor with the math of LennardJonesKernel = Kernel::lj, bit for bit.
TEST(Functors, UserLennardJonesEqualsBuiltInBitForBit) {
  for_each_case([](Engine& engine, const raycut::KernelOptions& options) {
    const raycut::Results want = engine.compute(Kernel::lj, options);
    std::vector<float> energy(engine.size(), -1.0f);
    const user::LjNoCombine p = user::lj_parameters(options, energy.data());
    raycut::for_each_pair(engine, user::Lj{p});
    EXPECT_TRUE(same_bits(energy, want.energy)) << first_difference(energy, want.energy);
    // Without combine() (so without mirror): each pair from both sides. The same bits where the
    // built-in kernel does so too (brute force), the same sums in another order on the cell list.
    std::vector<float> energy2(engine.size(), -1.0f);
    raycut::for_each_pair(engine, user::lj_parameters(options, energy2.data()));
    if (engine.method() == "brute-force") {
      EXPECT_TRUE(same_bits(energy2, want.energy)) << first_difference(energy2, want.energy);
    } else {
      for (std::size_t i = 0; i < energy2.size(); ++i) {
        if (std::isinf(want.energy[i])) {  // coincident points
          EXPECT_EQ(energy2[i], want.energy[i]) << "target " << i;
          continue;
        }
        ASSERT_NEAR(energy2[i], want.energy[i], 1e-5 * std::abs(want.energy[i]) + 1e-6)
            << "target " << i;
      }
    }
  });
}

// (b) Energy, force and virial of LennardJonesForceKernel = Kernel::lj_forces, bit for bit.
TEST(Functors, UserLennardJonesForcesEqualBuiltInBitForBit) {
  for_each_case([](Engine& engine, const raycut::KernelOptions& options) {
    const raycut::Results want = engine.compute(Kernel::lj_forces, options);
    const std::size_t n = engine.size();
    std::vector<float> energy(n, -1.0f), force(3 * n, -1.0f), virial(6 * n, -1.0f);
    raycut::for_each_pair(
        engine, user::LjForces{options.lj_sigma * options.lj_sigma, 4.0f * options.lj_epsilon,
                               energy.data(), force.data(), virial.data()});
    EXPECT_TRUE(same_bits(energy, want.energy)) << first_difference(energy, want.energy);
    EXPECT_TRUE(same_bits(force, want.force)) << first_difference(force, want.force);
    EXPECT_TRUE(same_bits(virial, want.virial)) << first_difference(virial, want.virial);
  });
}

// (c) init() seeds every target's state; no combine() needed on the CPU.
TEST(Functors, InitWithoutCombine) {
  static_assert(raycut::has_init<user::CountFromInit>::value);
  static_assert(!raycut::has_combine<user::CountFromInit>::value);
  // The pair call's form says what a functor reads; its options, what else it has.
  static_assert(raycut::uses_source<user::CountFromInit>::value &&
                !raycut::takes_shift<user::CountFromInit>::value);
  static_assert(!raycut::uses_source<user::Lj>::value && raycut::has_combine<user::Lj>::value &&
                raycut::vanishes_at_infinity<user::Lj>::value &&
                !raycut::has_combine<user::LjNoCombine>::value);
  static_assert(!raycut::uses_source<raycut::CountKernel>::value &&
                !raycut::vanishes_at_infinity<raycut::CountKernel>::value &&
                raycut::uses_source<raycut::SphForceKernel>::value);
  for_each_case([](Engine& engine, const raycut::KernelOptions&) {
    const raycut::Results want = engine.compute(Kernel::count);
    std::vector<std::uint32_t> got(engine.size(), 0);
    raycut::for_each_pair(engine, user::CountFromInit{1000, got.data()});
    for (std::size_t i = 0; i < got.size(); ++i)
      ASSERT_EQ(got[i], want.count[i] + 1000 + i % 5) << "target " << i;
  });
}

// Counts every call, to see that nothing runs.
struct Spy {
  using Accumulator = float;
  std::atomic<int>* pairs;
  std::atomic<int>* finishes;
  float* energy;
  void operator()(float& acc, std::uint32_t, std::uint32_t, raycut::Vec3, float) const {
    ++*pairs;
    acc += 1;
  }
  void finish(std::uint32_t i, float& acc) const {
    ++*finishes;
    energy[i] = acc;
  }
};

// (d) N = 0: nothing runs. N = 1: no pair, one finish with the initial state.
TEST(Functors, EmptyAndSingleParticle) {
  for (const char* method : cpu_methods) {
    SCOPED_TRACE(method);
    std::atomic<int> pairs{0}, finishes{0};
    Engine empty(method);
    empty.build({nullptr, 0, MemorySpace::host}, 1.0f);
    raycut::for_each_pair(empty, Spy{&pairs, &finishes, nullptr});
    EXPECT_EQ(pairs.load(), 0);
    EXPECT_EQ(finishes.load(), 0);

    const float xyz[3] = {0.25f, -1.0f, 3.0f};
    Engine one(method);
    one.build({xyz, 1, MemorySpace::host}, 1.0f);
    float energy = -1.0f;
    raycut::for_each_pair(one, Spy{&pairs, &finishes, &energy});
    EXPECT_EQ(pairs.load(), 0);
    EXPECT_EQ(finishes.load(), 1);
    EXPECT_EQ(energy, 0.0f);
    std::vector<float> lj(1, -1.0f), f(3, -1.0f), v(6, -1.0f);
    raycut::for_each_pair(one, user::LjForces{1, 4, lj.data(), f.data(), v.data()});
    EXPECT_EQ(lj, std::vector<float>(1, 0.0f));
    EXPECT_EQ(f, std::vector<float>(3, 0.0f));
    EXPECT_EQ(v, std::vector<float>(6, 0.0f));
  }
}

// A jittered lattice: random, but no pair close enough for Lennard-Jones to blow up.
std::vector<float> jittered_lattice(int m, double spacing, double jitter) {
  std::vector<float> xyz;
  std::uint64_t state = 12345;
  const auto next = [&] {  // uniform in [-1, 1)
    state = state * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state >> 11) * 0x1.0p-52 - 1.0;
  };
  for (int a = 0; a < m; ++a)
    for (int b = 0; b < m; ++b)
      for (int c = 0; c < m; ++c) {
        const int idx[3] = {a, b, c};
        for (int k = 0; k < 3; ++k)
          xyz.push_back(static_cast<float>(idx[k] * spacing + jitter * next()));
      }
  return xyz;
}

// The in-range pairs (i < j) as every method decides them: the shared float predicate.
std::vector<std::pair<std::size_t, std::size_t>> pairs_in_range(const std::vector<float>& xyz,
                                                                float cutoff) {
  std::vector<std::pair<std::size_t, std::size_t>> out;
  const std::size_t n = xyz.size() / 3;
  const float c2 = raycut::squared_cutoff(cutoff);
  for (std::size_t i = 0; i < n; ++i)
    for (std::size_t j = i + 1; j < n; ++j) {
      const float r2 =
          raycut::squared_distance(xyz[3 * j] - xyz[3 * i], xyz[3 * j + 1] - xyz[3 * i + 1],
                                   xyz[3 * j + 2] - xyz[3 * i + 2]);
      if (raycut::in_range(r2, c2)) out.emplace_back(i, j);
    }
  return out;
}

// (e) Kernel::lj_forces: force = -dE/dx (central differences of the double-precision total
// energy over the same pairs) and sum_i virial_i = sum_{i<j} (x_i - x_j) (x) f_ij, where f_ij is
// the force on i from j (kernels.hpp's convention), computed in double.
TEST(Functors, LennardJonesForcesAndVirialAgainstDoublePrecision) {
  const double eps = 1.5, sigma = 0.9;
  const float cutoff = 2.5f;
  const std::vector<float> xyz = jittered_lattice(6, 1.05, 0.12);
  const std::size_t n = xyz.size() / 3;
  const auto pairs = pairs_in_range(xyz, cutoff);
  ASSERT_GT(pairs.size(), 10 * n);

  // Total energy in double, particle k moved by h along axis a.
  const auto total_energy = [&](std::size_t k, int a, double h) {
    double e = 0;
    for (const auto& [i, j] : pairs) {
      double r2 = 0;
      for (int c = 0; c < 3; ++c) {
        double d = static_cast<double>(xyz[3 * j + c]) - xyz[3 * i + c];
        if (c == a && j == k) d += h;
        if (c == a && i == k) d -= h;
        r2 += d * d;
      }
      const double s6 = std::pow(sigma * sigma / r2, 3);
      e += 4 * eps * (s6 * s6 - s6);
    }
    return e;
  };
  // Virial in double, and the scale of its terms.
  double virial[6] = {0, 0, 0, 0, 0, 0}, virial_scale[6] = {0, 0, 0, 0, 0, 0};
  const int va[6] = {0, 1, 2, 0, 0, 1}, vb[6] = {0, 1, 2, 1, 2, 2};
  for (const auto& [i, j] : pairs) {
    double r[3], r2 = 0;  // r = x_j - x_i
    for (int c = 0; c < 3; ++c) {
      r[c] = static_cast<double>(xyz[3 * j + c]) - xyz[3 * i + c];
      r2 += r[c] * r[c];
    }
    const double s6 = std::pow(sigma * sigma / r2, 3);
    const double g = -24 * eps * s6 * (2 * s6 - 1) / r2;  // f_ij = g r (force on i from j)
    for (int k = 0; k < 6; ++k) {
      const double term = -r[va[k]] * g * r[vb[k]];  // (x_i - x_j) (x) f_ij
      virial[k] += term;
      virial_scale[k] += std::abs(term);
    }
  }

  for (const char* method : cpu_methods) {
    SCOPED_TRACE(method);
    Engine engine(method);
    engine.build({xyz.data(), n, MemorySpace::host}, cutoff);
    raycut::KernelOptions options;
    options.lj_epsilon = static_cast<float>(eps);
    options.lj_sigma = static_cast<float>(sigma);
    const raycut::Results r = engine.compute(Kernel::lj_forces, options);

    // Energy: each pair half on each atom, so the per-atom energies sum to the system's.
    double sum_energy = 0;
    for (float e : r.energy) sum_energy += e;
    const double e0 = total_energy(0, 0, 0.0);
    EXPECT_NEAR(sum_energy, e0, 1e-4 * std::abs(e0) + 1e-3);

    for (std::size_t k : {std::size_t{0}, std::size_t{37}, n / 2, n - 5, n - 1}) {
      for (int a = 0; a < 3; ++a) {
        const double h = 1e-6;
        const double want = -(total_energy(k, a, h) - total_energy(k, a, -h)) / (2 * h);
        const double got = r.force[3 * k + a];
        double norm = 0;
        for (int c = 0; c < 3; ++c) norm += double{r.force[3 * k + c]} * r.force[3 * k + c];
        EXPECT_NEAR(got, want, 1e-3 * std::sqrt(norm) + 1e-4) << "particle " << k << " axis " << a;
      }
    }

    double got_virial[6] = {0, 0, 0, 0, 0, 0};
    for (std::size_t i = 0; i < n; ++i)
      for (int k = 0; k < 6; ++k) got_virial[k] += r.virial[6 * i + k];
    for (int k = 0; k < 6; ++k)
      EXPECT_NEAR(got_virial[k], virial[k], 1e-4 * virial_scale[k]) << "virial component " << k;
  }
}

// (e'') Each pair once (option::mirror; the cell list computes lj_forces so) in periodic boxes,
// a skewed one among them, on one and on two threads: per-particle energy, force and virial
// against sums in double over the images enumerated here, and the same bits on a second run.
TEST(Functors, LennardJonesForcesOncePerPairAgainstDoublePrecisionImages) {
  const double eps = 1.5, sigma = 0.9;
  const float cutoff = 2.5f;
  const int m = 13;  // 2197 particles: enough for the pass to fork its threads
  const double spacing = 1.05, side = m * spacing;
  const std::vector<float> xyz = jittered_lattice(m, spacing, 0.12);
  const std::size_t n = xyz.size() / 3;
  raycut::Box skewed = raycut::Box::orthorhombic(side, side, side);
  skewed.cell[1][0] = 0.3 * side;  // b leans along x
  skewed.cell[2][1] = -0.2 * side;
  for (const raycut::Box& box : {raycut::Box::orthorhombic(side, side, side), skewed}) {
    // Per particle, in double: energy (half of each pair), force, virial and the scale of the
    // terms of each, over every image n a + p b + q c with |n|, |p|, |q| <= 2 in range.
    std::vector<double> want(10 * n, 0.0), scale(10 * n, 0.0);
    const double c2 = double{cutoff} * cutoff;
    for (std::size_t i = 0; i < n; ++i)
      for (std::size_t j = 0; j < n; ++j)
        for (int a = -2; a <= 2; ++a)
          for (int b = -2; b <= 2; ++b)
            for (int c = -2; c <= 2; ++c) {
              if (i == j && a == 0 && b == 0 && c == 0) continue;
              double r[3], r2 = 0;
              for (int k = 0; k < 3; ++k) {
                r[k] = double{xyz[3 * j + k]} - xyz[3 * i + k] + a * box.cell[0][k] +
                       b * box.cell[1][k] + c * box.cell[2][k];
                r2 += r[k] * r[k];
              }
              if (r2 >= c2) continue;
              const double s6 = std::pow(sigma * sigma / r2, 3);
              const double g = 24 * eps * s6 * (2 * s6 - 1) / r2;  // force on i: -g r
              const int va[6] = {0, 1, 2, 0, 0, 1}, vb[6] = {0, 1, 2, 1, 2, 2};
              double term[10];
              term[0] = 0.5 * 4 * eps * (s6 * s6 - s6);
              for (int k = 0; k < 3; ++k) term[1 + k] = -g * r[k];
              for (int k = 0; k < 6; ++k) term[4 + k] = 0.5 * g * r[va[k]] * r[vb[k]];
              for (int k = 0; k < 10; ++k) {
                want[10 * i + k] += term[k];
                scale[10 * i + k] += std::abs(term[k]);
              }
            }
    // The cell list takes each pair once; brute force, from each side (the reference pass).
    for (const auto& [method, threads] :
         {std::pair{"cell-list", 1}, std::pair{"cell-list", 2}, std::pair{"brute-force", 2}}) {
#if defined(_OPENMP)
      const int before = omp_get_max_threads();
      omp_set_num_threads(threads);
#endif
      SCOPED_TRACE(std::string(method) + ", threads " + std::to_string(threads) + ", skewed " +
                   std::to_string(box.cell[1][0] != 0));
      Engine engine(method);
      engine.build({xyz.data(), n, MemorySpace::host}, cutoff, box);
      raycut::KernelOptions options;
      options.lj_epsilon = static_cast<float>(eps);
      options.lj_sigma = static_cast<float>(sigma);
      const raycut::Results r = engine.compute(Kernel::lj_forces, options);
      const raycut::Results again = engine.compute(Kernel::lj_forces, options);
#if defined(_OPENMP)
      omp_set_num_threads(before);
#endif
      EXPECT_TRUE(same_bits(r.force, again.force) && same_bits(r.energy, again.energy) &&
                  same_bits(r.virial, again.virial));
      // Float vectors at the box's scale: r carries ~1e-7 L of rounding, which the steep
      // repulsion turns into ~1e-5 of the terms' scale; each-side and once-per-pair alike.
      double worst = 0;
      for (std::size_t i = 0; i < n; ++i)
        for (int k = 0; k < 10; ++k) {
          const double got = k == 0  ? r.energy[i]
                             : k < 4 ? r.force[3 * i + k - 1]
                                     : r.virial[6 * i + k - 4];
          worst = std::max(worst, std::abs(got - want[10 * i + k]) / (scale[10 * i + k] + 1e-6));
        }
      EXPECT_LT(worst, 1e-4);
      std::printf("%s, %d threads, skewed %d: largest error %.2e of the terms' scale\n", method,
                  threads, box.cell[1][0] != 0, worst);
    }
  }
}

// (e') KernelOptions::lj_shift: every pair's energy shifted to 0 at the cutoff, so the per-atom
// energies sum to E - P U(C) (P pairs, in double); forces and virial exactly as unshifted. `lj`
// (the paper's unshifted kernel) refuses the option.
TEST(Functors, LennardJonesShiftAtTheCutoff) {
  const double eps = 0.7, sigma = 1.1;
  const float cutoff = 2.5f;
  const std::vector<float> xyz = jittered_lattice(5, 1.1, 0.1);
  const auto pairs = pairs_in_range(xyz, cutoff);
  ASSERT_GT(pairs.size(), 100u);
  const double c2 = static_cast<double>(cutoff) * cutoff, uc = std::pow(sigma * sigma / c2, 3);
  double want = 0, scale = 0;
  for (const auto& [i, j] : pairs) {
    double r2 = 0;
    for (int c = 0; c < 3; ++c) {
      const double d = static_cast<double>(xyz[3 * j + c]) - xyz[3 * i + c];
      r2 += d * d;
    }
    const double u = std::pow(sigma * sigma / r2, 3);
    want += 4 * eps * (u * (u - 1) - uc * (uc - 1));
    scale += 4 * eps * (u * (u + 1));
  }
  for (const char* method : cpu_methods) {
    SCOPED_TRACE(method);
    Engine engine(method);
    engine.build({xyz.data(), xyz.size() / 3, MemorySpace::host}, cutoff);
    raycut::KernelOptions options;
    options.lj_epsilon = static_cast<float>(eps);
    options.lj_sigma = static_cast<float>(sigma);
    const raycut::Results plain = engine.compute(Kernel::lj_forces, options);
    options.lj_shift = true;
    const raycut::Results shifted = engine.compute(Kernel::lj_forces, options);
    double sum = 0, sum_plain = 0;
    for (float e : shifted.energy) sum += e;
    for (float e : plain.energy) sum_plain += e;
    EXPECT_NEAR(sum, want, 1e-5 * scale);
    // The shift alone: P U(C) (every pair is within the cutoff here, none shifted twice).
    EXPECT_NEAR(sum_plain - sum, pairs.size() * 4 * eps * uc * (uc - 1), 1e-5 * scale);
    EXPECT_EQ(shifted.force, plain.force);
    EXPECT_EQ(shifted.virial, plain.virial);
    try {
      engine.compute(Kernel::lj, options);
      ADD_FAILURE() << "lj accepted lj_shift";
    } catch (const raycut::Error& e) {
      EXPECT_EQ(e.code(), raycut::ErrorCode::invalid_argument);
      EXPECT_NE(std::string(e.what()).find("lj_shift"), std::string::npos) << e.what();
    }
  }
}

// (f) raycut::for_each_pair runs on the host only: GPU methods refuse with Error(unsupported).
// A translation unit that includes <raycut/pairs.hpp> without the Engine class runs a functor
// on an engine built here: the counts are Kernel::count's, and an engine not built is refused.
TEST(Functors, PairsHeaderNeedsOnlyADeclaredEngine) {
  const raycut::PointCloud cloud = raycut::make_family("uniform", 500, 0.3f, 11);
  for (const char* method : cpu_methods) {
    SCOPED_TRACE(method);
    Engine engine(method);
    engine.build({cloud.xyz.data(), cloud.size(), MemorySpace::host}, 0.3f);
    const std::vector<std::uint32_t> counts =
        neighbour_counts_through_pairs_header(engine, cloud.size());
    EXPECT_EQ(counts, engine.compute(Kernel::count).count);
    EXPECT_GT(std::accumulate(counts.begin(), counts.end(), std::uint64_t{0}), 0u);

    Engine unbuilt(method);
    try {
      neighbour_counts_through_pairs_header(unbuilt, 0);
      ADD_FAILURE() << "no exception for an engine not built";
    } catch (const raycut::Error& e) {
      EXPECT_EQ(e.code(), raycut::ErrorCode::invalid_argument) << e.what();
      EXPECT_NE(std::string(e.what()).find("before Engine::build"), std::string::npos) << e.what();
    }
  }
}

TEST(Functors, HostForEachPairRefusesGpuMethods) {
  const std::vector<float> xyz = {0, 0, 0, 0.5f, 0, 0, 0, 0.5f, 0};
  int tried = 0;
  for (const raycut::MethodDescription& m : raycut::list_methods()) {
    if (!m.available) continue;
    Engine engine(m.name);
    if (engine.space() == MemorySpace::host) continue;
    SCOPED_TRACE(m.name);
    ++tried;
    engine.build({xyz.data(), 3, MemorySpace::host}, 1.0f);
    std::vector<float> energy(3);
    try {
      raycut::for_each_pair(engine, user::lj_parameters({}, energy.data()));
      ADD_FAILURE() << "no exception";
    } catch (const raycut::Error& e) {
      EXPECT_EQ(e.code(), raycut::ErrorCode::unsupported) << e.what();
    }
  }
  if (tried == 0) GTEST_SKIP() << "no GPU method available here";
}

}  // namespace
