// Shifted-force Coulomb on the CPU cell list, through raycut::for_each_pair, checked against a
// double-precision O(N^2) loop. Exits 1 when the results are off.
#include <raycut/engine.hpp>
#include <raycut/pairs.hpp>

#include <cstdio>
#include <vector>

#include "coulomb.hpp"

int main() {
  const coulomb::System s = coulomb::make_system(4000, 0.25f);
  const std::size_t n = s.charge.size();

  raycut::Engine engine("cell-list");
  engine.build({s.xyz.data(), n, raycut::MemorySpace::host}, s.cutoff);
  std::vector<float> energy(n), force(3 * n);
  raycut::for_each_pair(
      engine, coulomb::ShiftedForce::make(s.charge.data(), s.cutoff, energy.data(), force.data()));

  double total = 0;
  for (float e : energy) total += e;
  const double worst = coulomb::worst_error(s, energy, force);
  std::printf("cell-list: %zu particles, total energy %.6f, worst relative error %.2e\n", n, total,
              worst);
  return worst < 1e-4 ? 0 : 1;
}
