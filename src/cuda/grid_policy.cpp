#include "cuda/grid_policy.hpp"

#include <algorithm>

namespace raycut::detail::cuda {
namespace {

struct Sizes {
  std::size_t n;
  const GridThresholds& t;
  // At most 8 cells per particle (plus a constant for tiny N): a dense table of <= 32 bytes each.
  bool few_cells(std::uint64_t cells) const { return cells <= 8ull * n + 4096; }
  // Up to 8 cells per particle, or up to 64 while the table stays within dense_cells_any_n.
  bool fits_dense(std::uint64_t cells) const {
    return few_cells(cells) || (cells <= 64ull * n && cells <= t.dense_cells_any_n);
  }
};

std::uint64_t cell_count(const GridGeometry& g) {
  return std::uint64_t{g.xgrid.dims[0]} * g.grid.dims[1] * g.grid.dims[2];
}

GridKernel lanes_kernel(LanesPerTarget lanes) {
  switch (lanes) {
    case LanesPerTarget::four:
      return GridKernel::lanes4;
    case LanesPerTarget::eight:
      return GridKernel::lanes8;
    case LanesPerTarget::sixteen:
      return GridKernel::lanes16;
    case LanesPerTarget::thirty_two:
      return GridKernel::lanes32;
    default:
      return GridKernel::thread;
  }
}

}  // namespace

GridPlan plan_grid(const GridPolicy& policy, const GridInput& input, const float lo[3],
                   const float hi[3], float cutoff, const GridThresholds& t) {
  const std::size_t n = input.n;
  const Sizes sizes{n, t};
  GridPlan plan;
  GridGeometry& view = plan.geometry;

  // Systems of a batch share the box [lo, hi] (each in its own frame) and stack their cells.
  const CellGrid coarse = make_cell_grid(lo, hi, cutoff, 1);
  const double density = static_cast<double>(n) /
                         (static_cast<double>(coarse.cell_count()) * std::max(input.systems, 1u));
  int k = static_cast<int>(policy.cell_width);  // CellWidth::cutoff = 1, half = 2, third = 3
  if (policy.cell_width == CellWidth::automatic) k = density >= t.fine_cells_density ? 2 : 1;
  view.grid = make_cell_grid(lo, hi, cutoff, k);
  if (input.systems > 1) {
    // reach empty layers between systems: no stencil row reaches the next system's cells.
    view.layer_cells = view.grid.dims[2];
    view.layer_stride = view.layer_cells + static_cast<std::uint32_t>(view.grid.reach);
    view.grid.dims[2] = input.systems * view.layer_stride;
  }

  // Narrower x cells, unless they alone would push a dense table over 8 cells per particle or
  // the table would be compact anyway (docs/grid.md: sphere surfaces).
  int split = policy.x_split > 0 ? policy.x_split : t.default_x_split[std::min(k, 2)];
  for (;; split /= 2) {
    view.xgrid = split > 1 ? make_cell_grid(lo, hi, cutoff, k * split) : view.grid;
    view.xgrid.dims[2] = view.grid.dims[2];
    if (split == 1 || policy.x_split > 0 || policy.layout != TableLayout::automatic ||
        sizes.few_cells(cell_count(view)) || !sizes.fits_dense(view.grid.cell_count()))
      break;
  }
  view.x_cells_per_cell = static_cast<float>(view.grid.width * view.xgrid.inverse_width);
  plan.cells = cell_count(view);
  switch (policy.layout) {
    case TableLayout::dense:
      plan.dense = plan.cells <= (1ull << 31);
      break;
    case TableLayout::compact:
      plan.dense = false;
      break;
    case TableLayout::automatic:
      plan.dense = sizes.fits_dense(plan.cells);
      break;
  }
  // Slack: relative 1e-5 and absolute 1e-5 cell, far above the float round-off of the predicate
  // (~2e-7 relative) and of the cell fractions (~1e-7 cell).
  view.reach_cells = static_cast<float>(cutoff * view.grid.inverse_width * (1.0 + 1e-5) + 1e-5);
  view.cull = policy.cull;

  // The dense build.
  if (policy.dense_build != DenseBuild::automatic) {
    plan.dense_build = policy.dense_build;
  } else if (n <= t.one_block_up_to && plan.cells + 1 <= t.one_block_cells) {
    plan.dense_build = DenseBuild::one_block;
  } else {
    // One or two particles per cell: placed cell by cell (more per cell would serialise a
    // thread's cell; more cells than particles would spend threads on empty ones).
    const bool by_cell = plan.cells <= n && 2 * plan.cells >= n;
    const std::size_t counting_limit = by_cell ? t.counting_sort_up_to : t.counting_sort_up_to - 1;
    plan.dense_build = n > counting_limit ? DenseBuild::radix
                                          : (by_cell ? DenseBuild::counting_by_cell
                                                     : DenseBuild::counting_by_particle);
  }

  // The kernel. The group kernel's row table holds (2 * 3 + 1)^2 rows: reach <= 3.
  const bool many_registers =
      policy.registers == RegisterBudget::unlimited ||
      (policy.registers == RegisterBudget::automatic && density >= t.many_registers_density);
  const GridKernel thread = many_registers ? GridKernel::thread_many_registers : GridKernel::thread;
  if (view.grid.reach > 3 || policy.lanes == LanesPerTarget::one) {
    plan.kernel = thread;
  } else if (policy.lanes != LanesPerTarget::automatic) {
    plan.kernel = lanes_kernel(policy.lanes);
  } else {
    const std::size_t targets = input.targets;
    plan.kernel =
        targets >= t.thread_kernel_from
            ? thread
            : (targets <= t.group_of_32_up_to ? GridKernel::lanes32 : GridKernel::lanes16);
  }
  return plan;
}

}  // namespace raycut::detail::cuda
