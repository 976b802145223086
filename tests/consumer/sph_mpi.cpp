// raycut::sph_mpi from the installed package: two steps of the distributed SPH solver on a small
// drop, on however many ranks run it (one here): every particle is gathered back on rank 0.
#include <raycut/mpi/sph.hpp>

#include <vector>

int main(int argc, char** argv) {
  MPI_Init(&argc, &argv);
  int rank = 0;
  MPI_Comm_rank(MPI_COMM_WORLD, &rank);
  int ok = 1;
  {
    raycut::mpi::SphSolver solver(MPI_COMM_WORLD, raycut::sph::small_drop(100), "cell-list");
    solver.step();
    solver.step();
    std::vector<float> x, v, rho, p;
    solver.copy_state(x, v, rho, p);
    ok = ok && (rank != 0 || x.size() == 300);
  }
  int all = 0;
  MPI_Allreduce(&ok, &all, 1, MPI_INT, MPI_MIN, MPI_COMM_WORLD);
  MPI_Finalize();
  return all ? 0 : 1;
}
