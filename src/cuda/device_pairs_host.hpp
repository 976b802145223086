// The small-system pass's enumeration run on the host: the same frames, image ranges, order,
// padding and count codes as raycut::list_pairs_small_systems, over host arrays, one row after
// another. For the tests: a machine without a GPU checks the pass's arithmetic against the double
// oracle (the warp-level placement is the GPU tests' part).
#pragma once

#include "raycut/device_pairs.hpp"

namespace raycut::detail {

// As list_pairs_small_systems, with every array of `systems` and `out` in host memory;
// synchronous.
void list_pairs_small_systems_on_host(const DeviceSystems& systems, double cutoff,
                                      const PairOptions& options, const StaticPairs& out);

}  // namespace raycut::detail
