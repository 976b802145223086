// What a distributed neighbour list costs against the single-rank engine's own
// (docs/distributed.md, "row schedule"): the LJ liquid of docs/benchmarks.md (density 0.8442,
// rc 2.5, uniform random in a periodic cube), cell-list, every rank `particles` / ranks of them.
// Per round, one after the other (so a noisy machine hits all alike):
//   list     DistributedEngine::neighbours() (shifts), the library's list over the row schedule;
//   functor  the same two passes (count, then fill at the offsets) as a caller's functors through
//            raycut::mpi::for_each_pair, the public functor pass;
//   engine   rank 0 alone: Engine::neighbours() (shifts) over all the particles in the box, the
//            engine's own list.
// Reports the minimum and the median over rounds of the CPU seconds (process CPU time, summed over
// ranks; rank 0's alone for `engine`) and the entries. Threads: OMP_NUM_THREADS.
//
//   mpirun -np 1 distributed_list [particles=40000] [rounds=5] [all-rows=0]
#include <mpi.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <random>
#include <string>
#include <vector>

#include "raycut/box.hpp"
#include "raycut/engine.hpp"
#include "raycut/mpi/distributed.hpp"
#include "raycut/mpi/pairs.hpp"

namespace {

// A caller's count and fill of a full list with global shifts, as raycut::mpi::for_each_pair
// sees a caller's functors.
struct CountRows {
  using Accumulator = std::uint32_t;
  std::uint64_t* offsets;  // counts at row + 1
  void operator()(Accumulator& count, std::uint32_t, raycut::Vec3, float) const { ++count; }
  void finish(std::uint32_t i, Accumulator& count) const { offsets[i + 1] = count; }
};

struct FillRows {
  using Accumulator = std::uint64_t;  // the row's next entry
  using options = raycut::functor_options<raycut::option::init>;
  const std::uint64_t* offsets;
  std::uint32_t* sources;
  std::int32_t* shifts;
  Accumulator init(std::uint32_t i) const { return offsets[i]; }
  void operator()(Accumulator& at, std::uint32_t, std::uint32_t j, raycut::Vec3, float,
                  const raycut::Shift& s) const {
    sources[at] = j;
    shifts[3 * at] = s.a;
    shifts[3 * at + 1] = s.b;
    shifts[3 * at + 2] = s.c;
    ++at;
  }
  void finish(std::uint32_t, Accumulator&) const {}
};

double cpu_seconds() {
  return static_cast<double>(std::clock()) / CLOCKS_PER_SEC;
}

double summed(double mine) {
  double total = 0;
  MPI_Allreduce(&mine, &total, 1, MPI_DOUBLE, MPI_SUM, MPI_COMM_WORLD);
  return total;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0, size = 1;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  MPI_Comm_size(MPI_COMM_WORLD, &size);
  const std::size_t n = argc > 1 ? std::strtoull(argv[1], nullptr, 10) : 40000;
  const int rounds = argc > 2 ? std::atoi(argv[2]) : 5;
  const bool all_rows = argc > 3 && std::atoi(argv[3]) != 0;
  if (n == 0 || rounds < 1) {
    if (rank == 0)
      std::fprintf(stderr, "distributed_list: particles (%zu) and rounds (%d) must be >= 1\n", n,
                   rounds);
    MPI_Finalize();
    return 2;
  }
  const float cutoff = 2.5f;
  const double length = std::cbrt(static_cast<double>(n) / 0.8442);
  const raycut::Box box = raycut::Box::orthorhombic(length, length, length);
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> u(0.0, length);
  std::vector<float> xyz(3 * n);
  for (float& x : xyz) x = static_cast<float>(u(rng));
  // Every size-th particle on each rank: build() migrates them to their domains.
  std::vector<float> mine;
  std::vector<std::uint64_t> ids;
  for (std::size_t i = rank; i < n; i += size) {
    ids.push_back(i);
    mine.insert(mine.end(), &xyz[3 * i], &xyz[3 * i] + 3);
  }
  raycut::mpi::DistributedOptions options;
  options.owned_rows_only = !all_rows;
  raycut::mpi::DistributedEngine engine(MPI_COMM_WORLD, options);
  engine.build({mine.data(), ids.size(), raycut::MemorySpace::host}, ids.data(), cutoff, box);
  raycut::Engine single("cell-list");
  if (rank == 0) single.build({xyz.data(), n, raycut::MemorySpace::host}, cutoff, box);

  raycut::ListOptions list_options;
  list_options.shifts = true;
  std::vector<double> list_s, functor_s, engine_s;
  std::uint64_t list_entries = 0, functor_entries = 0, engine_entries = 0;
  for (int round = 0; round < rounds; ++round) {
    MPI_Barrier(MPI_COMM_WORLD);
    double start = cpu_seconds();
    const raycut::mpi::DistributedList list = engine.neighbours(list_options);
    list_s.push_back(summed(cpu_seconds() - start));
    list_entries = list.indices.size();

    MPI_Barrier(MPI_COMM_WORLD);
    start = cpu_seconds();
    std::vector<std::uint64_t> offsets(engine.owned() + 1, 0);
    raycut::mpi::for_each_pair(engine, CountRows{offsets.data()});
    for (std::size_t t = 0; t < engine.owned(); ++t) offsets[t + 1] += offsets[t];
    std::vector<std::uint32_t> sources(offsets.back());
    std::vector<std::int32_t> shifts(3 * offsets.back());
    raycut::mpi::for_each_pair(engine, FillRows{offsets.data(), sources.data(), shifts.data()});
    functor_s.push_back(summed(cpu_seconds() - start));
    functor_entries = sources.size();

    if (rank == 0) {
      start = cpu_seconds();
      const raycut::NeighbourList own = single.neighbours(list_options);
      engine_s.push_back(cpu_seconds() - start);
      engine_entries = own.indices.size();
    }
  }
  const auto total = [](std::uint64_t mine_entries) {
    std::uint64_t all = 0;
    MPI_Allreduce(&mine_entries, &all, 1, MPI_UINT64_T, MPI_SUM, MPI_COMM_WORLD);
    return all;
  };
  list_entries = total(list_entries);
  functor_entries = total(functor_entries);
  if (rank == 0) {
    std::printf("%zu particles, %d ranks, %s, %d rounds: CPU s min / median, entries\n", n, size,
                all_rows ? "all rows" : "owned rows only", rounds);
    const auto row = [&](const char* name, const std::vector<double>& s, std::uint64_t entries) {
      std::printf("  %-8s %.3f / %.3f  %llu\n", name, *std::min_element(s.begin(), s.end()),
                  median(s), static_cast<unsigned long long>(entries));
    };
    row("list", list_s, list_entries);
    row("functor", functor_s, functor_entries);
    row("engine", engine_s, engine_entries);
  }
  MPI_Finalize();
  return 0;
}
