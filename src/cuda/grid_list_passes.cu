// The grid's passes of the list functors (grid_list_passes.hpp says why apart from grid.cu).
#include "cuda/grid_list_passes.hpp"

#include "raycut/detail/cuda/grid_pass.cuh"

namespace raycut::detail::cuda {
RAYCUT_GRID_LIST_FUNCTORS(RAYCUT_GRID_INSTANTIATE_RUN)
}  // namespace raycut::detail::cuda
