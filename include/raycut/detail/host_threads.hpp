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

}  // namespace raycut::detail
