// What a periodic pair costs on the CPU against an open one (docs/periodic.md, "CPU cost of a
// periodic pair"): the LJ liquid of docs/benchmarks.md (density 0.8442, rc 2.5, uniform random in a
// cube) built twice per round and method:
//   periodic  Engine::build(x, C, box) then run(lj_forces): the engine makes the images;
//   open      the same particles plus explicit copies of every image within the cutoff shell
//             (the engine's own set, in its order) as an open cloud: every point a target;
//   open-n    those points through the method directly (src/, not the public API), the first N
//             (the particles) the only targets: the periodic pass's very work without images;
//   queries   N query points (the particles moved by 0.37 along each axis, wrapped) over the
//             particles in the same periodic box: the query pass's cost per pair.
// Reports the minimum and the median over rounds (variants alternate, so a noisy machine hits
// both alike) of the build and lj_forces ms, pairs (from count), ns per pair (compute / pairs)
// and candidates per target (the points of the 27 cells around the target's own, counted here
// with the cell list's cell width). Threads: OMP_NUM_THREADS.
//
// kernel "lj_forces-each-side" ("count-each-side") times lj_forces (count) computed from both
// particles of every pair (raycut::for_each_pair with the kernel's functor less option::mirror),
// the pass of a functor without the option;
// "lj_forces-once" ("count-once") the kernel's own functor through the same call and buffers
// (the engine's run also allocates its results: at small N, compare these two).
//
// kernel "list" times the engine's CSR list with S (count and fill; not for open-n), "half-list"
// the same half (nor for queries), "half-any-list" the half list whose rows may follow the
// traversal (ListOptions::any_row: the half stencil); those rows report 0 ms.
//
//   periodic_cpu [particles=200000] [rounds=5] [method=cell-list]
//                [kernel=lj_forces|lj_forces-each-side|lj_forces-once|count|count-each-side|
//                 count-once|list|half-list|
//                 half-any-list]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <memory>
#include <random>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/method.hpp"
#include "raycut/box.hpp"
#include "raycut/engine.hpp"
#include "raycut/pairs.hpp"

namespace {

// A built-in kernel's functor from each side of a pair: without option::mirror.
template <class F>
struct EachSide {
  F f;
  using Accumulator = typename F::Accumulator;
  void operator()(Accumulator& acc, std::uint32_t i, raycut::Vec3 r, float r2) const {
    f(acc, i, r, r2);
  }
  void finish(std::uint32_t i, Accumulator& acc) const { f.finish(i, acc); }
};

struct Sample {
  double build_ms, compute_ms;
};

// The points of the 27 cells around each of the first `targets` points, per target.
double candidates_per_target(const std::vector<float>& xyz, std::size_t targets, float cutoff) {
  const double inverse = 1.0 / (cutoff * (1.0 + 1e-4));
  const auto key = [&](const float* p, int dx, int dy, int dz) {
    const auto c = [&](float x, int d) {
      return static_cast<std::int64_t>(std::floor(x * inverse)) + d + (1 << 20);
    };
    return (c(p[2], dz) << 42) | (c(p[1], dy) << 21) | c(p[0], dx);
  };
  std::unordered_map<std::int64_t, std::uint32_t> cells;
  for (std::size_t k = 0; k < xyz.size() / 3; ++k) ++cells[key(&xyz[3 * k], 0, 0, 0)];
  double total = 0;
  for (std::size_t t = 0; t < targets; ++t)
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (auto it = cells.find(key(&xyz[3 * t], dx, dy, dz)); it != cells.end())
            total += it->second;
  return total / static_cast<double>(targets);
}

// The particles, then each particle's images n != 0 (n lexicographic) whose coordinates lie in
// (-reach, L + reach) on every axis: the engine's points for a cube (src/core/images.cpp).
std::vector<float> with_images(const std::vector<float>& x, double side, double cutoff) {
  std::vector<float> out(x);
  const double reach = cutoff * (1 + 1e-4);
  for (std::size_t p = 0; p < x.size() / 3; ++p)
    for (int a = -1; a <= 1; ++a)
      for (int b = -1; b <= 1; ++b)
        for (int c = -1; c <= 1; ++c) {
          if (a == 0 && b == 0 && c == 0) continue;
          const int n[3] = {a, b, c};
          double q[3];
          bool keep = true;
          for (int d = 0; d < 3; ++d) {
            q[d] = x[3 * p + d] + n[d] * side;
            keep = keep && q[d] > -reach && q[d] < side + reach;
          }
          if (keep)
            for (double v : q) out.push_back(static_cast<float>(v));
        }
  return out;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  const std::size_t n = argc > 1 ? std::strtoull(argv[1], nullptr, 10) : 200000;
  const int rounds = argc > 2 ? std::atoi(argv[2]) : 5;
  const std::string method = argc > 3 ? argv[3] : "cell-list";
  const std::string kernel_name = argc > 4 ? argv[4] : "lj_forces";
  const raycut::Kernel kernel =
      kernel_name.rfind("count", 0) == 0 ? raycut::Kernel::count : raycut::Kernel::lj_forces;
  const float cutoff = 2.5f;
  const double side = std::cbrt(static_cast<double>(n) / 0.8442);
  std::mt19937_64 rng(1);
  std::uniform_real_distribution<double> u(0.0, side);
  std::vector<float> x(3 * n);
  for (float& v : x) {
    v = static_cast<float>(u(rng));
    if (v >= side) v = 0;  // rounding up to the side: the wrapped point is 0
  }
  const std::vector<float> open = with_images(x, side, cutoff);
  const raycut::Box box = raycut::Box::orthorhombic(side, side, side);
  const raycut::PositionsView periodic_view{x.data(), n, raycut::MemorySpace::host};
  const raycut::PositionsView open_view{open.data(), open.size() / 3, raycut::MemorySpace::host};

  std::vector<float> q(x);
  for (float& v : q) v = static_cast<float>(std::fmod(v + 0.37, side));
  raycut::Systems with_queries = raycut::Systems::periodic(box);
  with_queries.queries = {q.data(), n, raycut::MemorySpace::host};
  raycut::Engine periodic(method), plain(method), queries(method);
  const std::unique_ptr<raycut::detail::Method> direct = raycut::detail::make_cell_list_cpu();
  const raycut::detail::Points open_n{open.data(), open.size() / 3, n, {}};
  constexpr int variants = 4;
  const char* names[variants] = {"periodic", "open", "open-n", "queries"};
  const std::size_t targets[variants] = {n, open.size() / 3, n, n};
  using Clock = std::chrono::steady_clock;
  const auto ms = [](Clock::time_point a, Clock::time_point b) {
    return std::chrono::duration<double, std::milli>(b - a).count();
  };
  const auto engine_of = [&](int v) -> raycut::Engine& {
    return v == 0 ? periodic : v == 1 ? plain : queries;
  };
  // Variant v built; its build ms.
  const auto build = [&](int v) {
    if (v == 0) periodic.build(periodic_view, cutoff, box);
    if (v == 1) plain.build(open_view, cutoff);
    if (v == 3) queries.build(periodic_view, cutoff, with_queries);
    if (v != 2) return engine_of(v).last_timings().build_ms;
    const auto start = Clock::now();
    direct->build_points(open_n, cutoff);
    return ms(start, Clock::now());
  };
  const bool list =
      kernel_name == "list" || kernel_name == "half-list" || kernel_name == "half-any-list";
  raycut::NeighbourListBuffer list_buffer;
  std::vector<std::uint32_t> counts;  // the -each-side and -once kernels' outputs
  std::vector<float> energy, force, virial;
  const bool each_side = kernel_name.find("-each-side") != std::string::npos;
  const bool once = kernel_name.find("-once") != std::string::npos;
  // Runs `kernel` on variant v; its ms.
  const auto run = [&](int v, raycut::Kernel kernel) {
    if (list && kernel != raycut::Kernel::count) {
      raycut::ListOptions options;
      options.shifts = true;
      options.half = kernel_name != "list";
      options.any_row = kernel_name == "half-any-list";
      if (v == 2 || (v == 3 && options.half)) return 0.0;  // no list, no half list of queries
      const auto start = Clock::now();
      engine_of(v).neighbours(list_buffer, options);
      return ms(start, Clock::now());
    }
    if (each_side || once) {
      if (v == 2) return 0.0;
      raycut::Engine& e = engine_of(v);
      counts.resize(e.size()), energy.resize(e.size()), force.resize(3 * e.size());
      virial.resize(6 * e.size());
      const raycut::KernelOutputs out{counts.data(), energy.data(), force.data(), virial.data()};
      const raycut::CountKernel count{counts.data()};
      const raycut::LennardJonesForceKernel lj =
          raycut::LennardJonesForceSpec::make({}, cutoff * cutoff, out);
      const auto start = Clock::now();
      if (kernel == raycut::Kernel::count && once)
        raycut::for_each_pair(e, count);
      else if (kernel == raycut::Kernel::count)
        raycut::for_each_pair(e, EachSide<raycut::CountKernel>{count});
      else if (once)
        raycut::for_each_pair(e, lj);
      else
        raycut::for_each_pair(e, EachSide<raycut::LennardJonesForceKernel>{lj});
      return ms(start, Clock::now());
    }
    if (v != 2) {
      raycut::Engine& e = engine_of(v);
      e.run(kernel);
      return e.last_timings().compute_ms;
    }
    const auto start = Clock::now();
    direct->compute(kernel, {});
    return ms(start, Clock::now());
  };
  std::uint64_t pairs[variants] = {0, 0, 0, 0};
  for (int v = 0; v < variants; ++v) {
    build(v);
    if (v == 2)
      direct->compute(raycut::Kernel::count, {});
    else
      engine_of(v).run(raycut::Kernel::count);
    const raycut::ResultsView r = v == 2 ? direct->results_view() : engine_of(v).results_view();
    for (std::size_t i = 0; i < targets[v]; ++i) pairs[v] += r.count[i];
  }
  std::vector<Sample> samples[variants];
  for (int round = 0; round < rounds; ++round)
    for (int v = 0; v < variants; ++v) {
      const double build_ms = build(v);
      samples[v].push_back({build_ms, run(v, kernel)});
    }
  const char* threads = std::getenv("OMP_NUM_THREADS");
  std::printf("# %s, %s, N = %zu, side %.3f, rc %.1f, OMP_NUM_THREADS=%s, %d rounds\n",
              method.c_str(), kernel_name.c_str(), n, side, cutoff, threads ? threads : "(unset)",
              rounds);
  std::printf(
      "variant,targets,points,pairs,candidates_per_target,build_ms_min,build_ms_median,"
      "kernel_ms_min,kernel_ms_median,ns_per_pair_min,ns_per_pair_median\n");
  for (int v = 0; v < variants; ++v) {
    std::vector<double> b, c;
    for (const Sample& s : samples[v]) {
      b.push_back(s.build_ms);
      c.push_back(s.compute_ms);
    }
    const double cmin = *std::min_element(c.begin(), c.end()), cmed = median(c);
    std::printf("%s,%zu,%zu,%llu,%.1f,%.2f,%.2f,%.2f,%.2f,%.2f,%.2f\n", names[v], targets[v],
                open.size() / 3, static_cast<unsigned long long>(pairs[v]),
                candidates_per_target(open, targets[v], cutoff),
                *std::min_element(b.begin(), b.end()), median(b), cmin, cmed, 1e6 * cmin / pairs[v],
                1e6 * cmed / pairs[v]);
  }
}
