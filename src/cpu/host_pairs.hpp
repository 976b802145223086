// The one CPU pair loop: every CPU method describes its candidates with a `visit` callable and
// this file applies the shared predicate, the kernel and the output layout.
//
// visit(i, f) must call f(j, xyz_j) for every candidate source j of target i (j == i allowed,
// skipped here), each j at most once.
#pragma once

#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/validation.hpp"
#include "raycut/engine.hpp"
#include "raycut/kernels.hpp"
#include "raycut/predicate.hpp"

namespace raycut::detail {

template <class Visit, class F>
void for_each_in_range(std::size_t i, const float* xyz, float cutoff_squared, Visit& visit,
                       F&& on_pair) {
  const float xi = xyz[3 * i], yi = xyz[3 * i + 1], zi = xyz[3 * i + 2];
  visit(i, [&](std::size_t j, const float* xj) {
    if (j == i) return;
    const float dx = xj[0] - xi, dy = xj[1] - yi, dz = xj[2] - zi;
    const float r2 = squared_distance(dx, dy, dz);
    if (in_range(r2, cutoff_squared)) on_pair(j, dx, dy, dz, r2);
  });
}

// Host results seen through a ResultsView.
inline ResultsView view_of(const Results& r) {
  auto data = [](const auto& v) { return v.empty() ? nullptr : v.data(); };
  return {data(r.count), data(r.energy), data(r.force), MemorySpace::host};
}

template <class Visit>
Results host_compute(std::size_t n, const float* xyz, float cutoff, Kernel kernel,
                     const KernelOptions& options, Visit visit) {
  const float c2 = squared_cutoff(cutoff);
  Results out;
  with_kernel(kernel, options, c2, [&](auto k) {
    using K = decltype(k);
    if constexpr (K::has_count) out.count.assign(n, 0);
    if constexpr (K::has_energy) out.energy.assign(n, 0.0f);
    if constexpr (K::has_force) out.force.assign(3 * n, 0.0f);
#pragma omp parallel for schedule(dynamic, 256)
    for (std::size_t i = 0; i < n; ++i) {
      Accumulator acc;
      for_each_in_range(
          i, xyz, c2, visit, [&](std::size_t j, float dx, float dy, float dz, float r2) {
            k(acc, static_cast<std::uint32_t>(i), static_cast<std::uint32_t>(j), dx, dy, dz, r2);
          });
      k.finish(acc);
      if constexpr (K::has_count) out.count[i] = acc.count;
      if constexpr (K::has_energy) out.energy[i] = acc.energy;
      if constexpr (K::has_force) {
        out.force[3 * i] = acc.fx;
        out.force[3 * i + 1] = acc.fy;
        out.force[3 * i + 2] = acc.fz;
      }
    }
  });
  return out;
}

// Two passes (count, then fill) so the list is exactly sized and built in parallel.
template <class Visit>
NeighbourList host_neighbours(std::size_t n, const float* xyz, float cutoff, Visit visit) {
  const float c2 = squared_cutoff(cutoff);
  NeighbourList list;
  list.offsets.assign(n + 1, 0);
#pragma omp parallel for schedule(dynamic, 256)
  for (std::size_t i = 0; i < n; ++i) {
    std::uint64_t c = 0;
    for_each_in_range(i, xyz, c2, visit, [&](std::size_t, float, float, float, float) { ++c; });
    list.offsets[i + 1] = c;
  }
  for (std::size_t i = 0; i < n; ++i) list.offsets[i + 1] += list.offsets[i];
  allocate_indices(list, list.offsets[n]);
#pragma omp parallel for schedule(dynamic, 256)
  for (std::size_t i = 0; i < n; ++i) {
    std::uint64_t slot = list.offsets[i];
    for_each_in_range(i, xyz, c2, visit, [&](std::size_t j, float, float, float, float) {
      list.indices[slot++] = static_cast<std::uint32_t>(j);
    });
  }
  return list;
}

}  // namespace raycut::detail
