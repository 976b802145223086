// The grid's choices, apart from its algorithms: what can be chosen (GridPolicy, every field
// `automatic` by default) and how the automatic choices are made from the box and N
// (plan_grid). The thresholds are measured, not derived: docs/grid.md has every measurement
// behind them (H100, bench/results/h100/grid-tune-*.csv); bench/grid_tune.cpp measures the
// alternatives by forcing a policy. Host-only.
#pragma once

#include <cstddef>
#include <cstdint>

#include "raycut/detail/pair_pass.hpp"

namespace raycut::detail::cuda {

enum class CellWidth { automatic, cutoff, half_cutoff, third_cutoff };  // C / k, reach k
enum class TableLayout { automatic, dense, compact };
enum class DenseBuild {
  automatic,
  counting_by_particle,  // counting sort, each particle placed by rank within its cell
  radix,                 // radix sort of (key, index), run ends and a prefix maximum
  one_block,             // the whole counting sort in one block (small inputs)
  counting_by_cell,      // counting sort, each cell's particles placed together (coalesced)
};
enum class LanesPerTarget { automatic, one, four, eight, sixteen, thirty_two };
enum class RegisterBudget { automatic, compiler_default, unlimited };

struct GridPolicy {
  CellWidth cell_width = CellWidth::automatic;
  int x_split = 0;   // x cells this many times narrower than y, z cells; 0: automatic
  bool cull = true;  // per target: skip rows out of reach, trim each row in x
  TableLayout layout = TableLayout::automatic;
  DenseBuild dense_build = DenseBuild::automatic;
  LanesPerTarget lanes = LanesPerTarget::automatic;
  RegisterBudget registers = RegisterBudget::automatic;
};

// 1, 4, 8, 16, 32 lanes as a LanesPerTarget (0 or anything else: automatic).
inline LanesPerTarget lanes_per_target(int lanes) {
  switch (lanes) {
    case 1:
      return LanesPerTarget::one;
    case 4:
      return LanesPerTarget::four;
    case 8:
      return LanesPerTarget::eight;
    case 16:
      return LanesPerTarget::sixteen;
    case 32:
      return LanesPerTarget::thirty_two;
    default:
      return LanesPerTarget::automatic;
  }
}

// The automatic choices' thresholds (docs/grid.md, "The choices and their measurements").
struct GridThresholds {
  // Cells C/2 wide (reach 2) from this many particles per C-cell of the box, else C wide.
  double fine_cells_density = 24.0;
  // x cells 1, 2 or 4 times narrower for reach 0 (unused), 1 and 2.
  int default_x_split[3] = {1, 2, 4};
  // The thread kernel with every register it wants from this many particles per C-cell.
  double many_registers_density = 8.0;
  // A thread per target from this many targets; below, 16 lanes, and 32 up to group_of_32.
  std::size_t thread_kernel_from = 65536 + 1;
  std::size_t group_of_32_up_to = 8192;
  // The dense table by counting sort up to this many particles (by cell: included), radix above.
  std::size_t counting_sort_up_to = std::size_t{1} << 20;
  // The whole dense build in one block up to this many particles and cells + 1.
  std::size_t one_block_up_to = 4096;
  std::uint64_t one_block_cells = 131072;
  // A dense table at most 8 cells per particle, or 64 while within this many cells.
  std::uint64_t dense_cells_any_n = std::uint64_t{1} << 24;
};

// What a build does, decided before any table is built.
struct GridPlan {
  GridGeometry geometry;
  std::uint64_t cells = 0;  // xgrid cells x y cells x z cells
  bool dense = true;
  DenseBuild dense_build = DenseBuild::counting_by_particle;  // when dense
  GridKernel kernel = GridKernel::thread;
};

// What the grid is built over: n points, the first `targets` of them targets, in `systems`
// independent systems (batches: each its own layer of z cells).
struct GridInput {
  std::size_t n = 0;
  std::size_t targets = 0;
  std::uint32_t systems = 1;
};

GridPlan plan_grid(const GridPolicy& policy, const GridInput& input, const float lo[3],
                   const float hi[3], float cutoff, const GridThresholds& thresholds = {});

}  // namespace raycut::detail::cuda
