// raycut::mpi from the installed package: two particles 0.5 apart across the periodic face of a
// box of 4, on however many ranks run it (one here): each has one neighbour. Links raycut::mpi
// alone (no SPH library).
#include <raycut/mpi/distributed.hpp>

#include <cstdio>
#include <vector>

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  int ok = 1;
  {
    raycut::mpi::DistributedEngine engine(MPI_COMM_WORLD);
    std::vector<float> xyz = {0.2f, 1, 1, 3.7f, 1, 1};
    std::vector<std::uint64_t> ids = {0, 1};
    const std::size_t n = rank == 0 ? 2 : 0;
    engine.build({xyz.data(), n, raycut::MemorySpace::host}, ids.data(), 1.0f,
                 raycut::Box::orthorhombic(4, 4, 4));
    const raycut::Results r = engine.compute(raycut::Kernel::count);
    for (std::uint32_t c : r.count) ok = ok && c == 1;
    std::printf("rank %d owns %zu, counts ok %d\n", rank, engine.owned(), ok);
  }
  int all = 0;
  MPI_Allreduce(&ok, &all, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
  MPI_Finalize();
  return all ? 0 : 1;
}
