// Factories of the CUDA methods (host-only declarations; the classes live in their .cu files).
#pragma once

#include <memory>

#include "core/method.hpp"

namespace raycut::detail::cuda {

std::unique_ptr<Method> make_brute_force();

// The seed paper's dense grid (cells of width C over the whole box), for comparison.
std::unique_ptr<Method> make_grid_paper();

// The production grid; its knobs are fixed by measurement (docs/grid.md). GridOptions exists so
// that bench/grid_tune.cpp can measure the alternatives; users get the defaults.
struct GridOptions {
  int cells_per_cutoff = 0;  // cells of width C / k, searched `k` cells around; 0: automatic
  int x_split = 0;           // x cells this many times narrower than y, z cells; 0: automatic
  bool cull = true;          // per-target: skip rows of cells out of reach, trim each row in x
  int layout = 0;            // 0: automatic, 1: dense cell table, 2: compact (hashed rows)
  // 1: a thread per target; 4, 8, 16, 32: lanes sharing each target; 0: automatic.
  int lanes_per_target = 0;
  // The thread kernel's registers: 0: automatic, 1: the compiler's default budget, 2: as many as
  // it wants.
  int thread_registers = 0;
  // The dense table from 0: automatic, 1: a counting sort placing particle by particle, 2: a
  // radix sort, 3: a counting sort in one block (small inputs), 4: a counting sort placing cell
  // by cell.
  int dense_build = 0;
};
std::unique_ptr<Method> make_grid_with(const GridOptions& options);
std::unique_ptr<Method> make_grid();

}  // namespace raycut::detail::cuda
