// When a CPU loop forks an OpenMP team: only over enough work to pay for it. Waking a team costs
// microseconds, and on a loaded machine its idle threads spin-wait (OMP_WAIT_POLICY) on the cores
// the call needs: a 108-atom periodic list on 2 busy cores took 44 ms with a team and 0.2 ms
// without. Pair passes go parallel from parallel_targets targets (each visits ~10-100
// candidates), flat loops over particles from parallel_items. OMP_NUM_THREADS caps the team.
#pragma once

#include <cstddef>

namespace raycut::detail {

inline constexpr std::size_t parallel_targets = 2048;
inline constexpr std::size_t parallel_items = 65536;

// body(i) for every i in [0, n): over an OpenMP team from `parallel_from` items (chunk 0: static
// schedule, else dynamic in chunks of `chunk`), below that on the calling thread without entering
// a parallel region. A region whose `if` clause is false still runs a team of one, and libgomp
// ends every team with a barrier whose futex wake is a system call: 0.4 us each on a 2-core VM,
// seven of them in a 1-atom cell's list (docs/limits.md, "OpenMP teams on the CPU").
template <class Body>
void for_each_index(std::size_t n, std::size_t parallel_from, std::size_t chunk, Body&& body) {
#if defined(_OPENMP)
  if (n >= parallel_from) {
    if (chunk == 0) {
#pragma omp parallel for schedule(static)
      for (std::size_t i = 0; i < n; ++i) body(i);
    } else {
#pragma omp parallel for schedule(dynamic, chunk)
      for (std::size_t i = 0; i < n; ++i) body(i);
    }
    return;
  }
#else
  (void)parallel_from;
  (void)chunk;
#endif
  for (std::size_t i = 0; i < n; ++i) body(i);
}

}  // namespace raycut::detail
