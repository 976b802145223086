// The grid's passes of the list functors, compiled in grid_list_passes.cu rather than with the
// rest of the grid in grid.cu: the two then compile in parallel. grid.cu alone took 7 minutes
// (its kernels are instantiated per functor, image mode, table and kernel shape), and was the
// critical path of every build. Which functors: the ones a list, a static list or a padded list
// runs (device_results.cuh); a functor missing here is still compiled, in grid.cu.
#pragma once

#include "core/list_functors.hpp"
#include "raycut/detail/pair_pass.hpp"

#include <cuda_runtime.h>

// clang-format off
#define RAYCUT_GRID_LIST_FUNCTORS(X)          \
  X(::raycut::detail::ListCount)              \
  X(::raycut::detail::FilteredListCount)      \
  X(::raycut::detail::PlainFilteredListCount) \
  X(::raycut::detail::ListFill)               \
  X(::raycut::detail::PlainListFill)          \
  X(::raycut::detail::IndexFill<true>)        \
  X(::raycut::detail::IndexFill<false>)       \
  X(::raycut::detail::PaddedFill)             \
  X(::raycut::detail::PlainPaddedFill<true>)  \
  X(::raycut::detail::PlainPaddedFill<false>)
// clang-format on

// extern (grid.cu) or an explicit instantiation (grid_list_passes.cu) of run_grid<F>.
#define RAYCUT_GRID_DECLARE_RUN(F) \
  extern template void run_grid<F>(const PairPass&, const F&, cudaStream_t);
#define RAYCUT_GRID_INSTANTIATE_RUN(F) \
  template void run_grid<F>(const PairPass&, const F&, cudaStream_t);
