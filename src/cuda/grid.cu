// grid: the production CUDA grid. Memory O(N) whatever the distribution, exact full semantics.
//
// Build: bounding box (one read back), a cell key per particle (row-major, so the cells of one
// x row are consecutive keys), the particles in cell order (within a cell by index: the layout,
// and every sum, is the same on every run) as float4 (w = original index), and a cell table:
//   dense   when the box has at most 8 cells per particle (or 64 within 2^24 cells): start[c]
//           for every cell c (+1 entry), so the particles of cells [a, b] of a row are slots
//           [start[a], start[b + 1]). Built by a counting sort below 2^20 particles (atomics,
//           then ranks by index within each cell; in one block up to 4096 particles; placed cell
//           by cell at one or two particles per cell, then up to 2^20 included), by a radix sort
//           of (key, index) above;
//   compact otherwise (a far outlier, a sphere surface at fine cells): a radix sort, the sorted
//           unique cell keys with their first slots, and a hash table from row (y, z) to that
//           row's run of unique cells; a row's [a, b] is then two binary searches in its run.
// Cells are C/k wide in y and z (k = 1 or 2 = reach, by density) and x_split times narrower in
// x: a row of x cells is one range of slots whatever their width, so narrow x cells trim each
// row closer to the target's sphere at no cost in rows.
// Compute: targets in sorted order (neighbouring lanes share cells). Each target visits the
// (2k+1)^2 rows around it, skips those out of reach of its actual position and trims each row to
// the x cells its sphere can touch, leaving one contiguous range of float4 per row. Large inputs
// run a thread per target; small ones (<= 64Ki targets) let 16 or 32 lanes share each target so
// that they still fill the GPU. Culling is conservative by construction (slack far above float
// round-off); the shared predicate decides every pair; self is excluded by slot. docs/grid.md
// has the measurements behind each choice.
#include <math_constants.h>
#include <cub/block/block_scan.cuh>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <cub/device/device_select.cuh>
#include <cuda/functional>
#include <cuda/std/functional>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <type_traits>

#include "core/cell_grid.hpp"
#include "cuda/device_results.cuh"
#include "cuda/grid_common.cuh"
#include "cuda/methods.hpp"
#include "raycut/predicate.hpp"

namespace raycut::detail::cuda {
namespace {

using Slot = std::uint32_t;
constexpr int block_size = 128;
constexpr std::uint64_t empty_row = ~std::uint64_t{0};

// The automatic choices, from the measurements in docs/grid.md (H100):
// - cells C/2 wide (reach 2) once a box of C-cells holds at least this many particles per cell
//   on average, else cells C wide: finer cells cut candidates by 2x but cost rows and sort bits;
constexpr double fine_cells_density = 24.0;
// - x cells 2 (C cells) or 4 (C/2 cells) times narrower than y and z cells: rows trimmed closer
//   to the sphere, for one more sort bit or two;
constexpr int default_x_split[3] = {1, 2, 4};
// - the thread kernel with the registers it wants (52: fewer warps, each with more loads in
//   flight) from this many particles per C-cell of the box on average, else within the
//   compiler's default budget (42: more warps), by measurement: uniform beta=32 p=8, 32:
//   0.065 / 0.068, 0.450 / 0.464 ms; sphere surfaces (sparse boxes) alpha=64 p=4: 0.201 / 0.195;
//   alpha=128 p=1: 0.338 / 0.323;
constexpr double many_registers_density = 8.0;
// - a thread per target from this many targets on; below, G lanes share each target (the
//   group kernel) so that small inputs still fill the GPU.
constexpr std::size_t thread_kernel_from = 65536 + 1;
constexpr std::size_t group_of_32_up_to = 8192;
// - the dense table from a counting sort up to this many particles, from a radix sort above: the
//   counting sort's scattered atomics lose to the sort's streaming passes at large N. Placed cell
//   by cell (one or two particles per cell) it wins up to 2^20 included (0.119 against 0.131 ms;
//   2^21: 0.216 against 0.205); placed particle by particle, only below (2^20: 0.157 / 0.133).
constexpr std::size_t counting_sort_up_to = std::size_t{1} << 20;
// - the whole dense build in one block up to this many particles and cells + 1 (launches cost
//   more than the work there);
constexpr int small_build_block = 1024;
constexpr std::size_t small_build_up_to = 4096;
constexpr std::uint64_t small_build_cells = 131072;
// - the dense cell table when it has at most 8 cells per particle, or up to 64 while it has at
//   most this many cells (64 MiB); else the compact table (Grid::fits_dense).
constexpr std::uint64_t dense_cells_any_n = std::uint64_t{1} << 24;

// What every query kernel needs to know about the grid. Cells are anisotropic: `grid` gives the
// y and z cells (C/k wide), `xgrid` the x cells, x_split times narrower; a row of x cells is one
// range of slots whatever their width, so narrow x cells trim rows closer to the sphere for free.
struct GridView {
  CellGrid grid, xgrid;
  float x_cells_per_cell;  // xgrid cells per grid cell, along x
  float reach_cells;       // the cutoff in cell units, inflated so that culling stays conservative
  bool cull;
};

// The particles of cells [xa, xb] of row `row` (row = iz * dims[1] + iy) are slots [s0, s1).
struct DenseTable {
  const Slot* start;  // cell_count + 1 entries
  __device__ __forceinline__ bool range(std::uint64_t row, std::uint32_t dims0, std::uint32_t xa,
                                        std::uint32_t xb, Slot& s0, Slot& s1) const {
    const std::uint64_t base = row * dims0;
    s0 = start[base + xa];
    s1 = start[base + xb + 1];
    return true;  // possibly empty (s0 == s1): the scan then does nothing
  }
};

__device__ __forceinline__ std::uint64_t row_hash(std::uint64_t row, int shift) {
  return (row * 0x9E3779B97F4A7C15ull) >> shift;
}

struct CompactTable {
  const std::uint64_t* cell_keys;  // non-empty cells, ascending
  const Slot* cell_start;          // runs + 1 entries
  const std::uint64_t* row_keys;   // hash table: row id, or empty_row
  const uint2* row_cells;          // hash table: the row's unique cells [x, y)
  std::uint64_t mask;
  int shift;

  __device__ __forceinline__ bool range(std::uint64_t row, std::uint32_t dims0, std::uint32_t xa,
                                        std::uint32_t xb, Slot& s0, Slot& s1) const {
    std::uint64_t h = row_hash(row, shift);
    uint2 cells;
    for (;;) {
      const std::uint64_t k = row_keys[h];
      if (k == row) {
        cells = row_cells[h];
        break;
      }
      if (k == empty_row) return false;
      h = (h + 1) & mask;
    }
    const std::uint64_t base = row * dims0;
    const std::uint32_t lo = lower_bound(cells.x, cells.y, base + xa);
    const std::uint32_t hi = lower_bound(lo, cells.y, base + xb + 1);
    if (lo == hi) return false;
    s0 = cell_start[lo];
    s1 = cell_start[hi];
    return true;
  }

  __device__ __forceinline__ std::uint32_t lower_bound(std::uint32_t first, std::uint32_t last,
                                                       std::uint64_t key) const {
    while (first < last) {
      const std::uint32_t mid = first + (last - first) / 2;
      if (cell_keys[mid] < key)
        first = mid + 1;
      else
        last = mid;
    }
    return first;
  }
};

// Distance, in cell units, from a target at fraction f of its cell to the slab d cells away.
__device__ __forceinline__ float slab_distance(int d, float f) {
  return d > 0 ? static_cast<float>(d) - f : (d < 0 ? f - static_cast<float>(d + 1) : 0.0f);
}

// Where a target sits: its cell and its fraction of the way across it, per axis.
struct TargetCell {
  int cell[3];
  float frac[3];
};

__device__ __forceinline__ TargetCell locate(const GridView& view, const float4& p) {
  TargetCell c;
  const float pc[3] = {p.x, p.y, p.z};
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    const CellGrid& g = a == 0 ? view.xgrid : view.grid;
    c.cell[a] = static_cast<int>(g.coord(pc[a], a));
    c.frac[a] = static_cast<float>((static_cast<double>(pc[a]) - g.origin[a]) * g.inverse_width -
                                   c.cell[a]);
  }
  return c;
}

// Row-major key of the cell holding (x, y, z): the x cells of a row are consecutive keys.
__host__ __device__ __forceinline__ std::uint64_t cell_key(const GridView& view, float x, float y,
                                                           float z) {
  const CellGrid& g = view.grid;
  return (static_cast<std::uint64_t>(g.coord(z, 2)) * g.dims[1] + g.coord(y, 1)) *
             view.xgrid.dims[0] +
         view.xgrid.coord(x, 0);
}

// The slots [s0, s1) of row (dz, dy) around the target, trimmed in x to the cells its sphere
// can reach; false when the row is outside the grid or out of reach (an empty row may come back
// as s0 == s1).
template <class Table>
__device__ __forceinline__ bool row_range(const GridView& view, const Table& table,
                                          const TargetCell& c, int dz, int dy, Slot& s0, Slot& s1) {
  const CellGrid& g = view.grid;
  const int jz = c.cell[2] + dz, jy = c.cell[1] + dy;
  if (jz < 0 || jz >= static_cast<int>(g.dims[2]) || jy < 0 || jy >= static_cast<int>(g.dims[1]))
    return false;
  const int x_reach = view.xgrid.reach;
  int xa = c.cell[0] - x_reach, xb = c.cell[0] + x_reach;
  if (view.cull) {
    const float rc = view.reach_cells, rc2 = rc * rc;
    const float ez = slab_distance(dz, c.frac[2]), ey = slab_distance(dy, c.frac[1]);
    const float e2 = ez * ez + ey * ey;
    if (ez >= rc || ey >= rc || e2 >= rc2) return false;
    const float rx = sqrtf(rc2 - e2) * view.x_cells_per_cell;
    xa = max(xa, c.cell[0] + static_cast<int>(floorf(c.frac[0] - rx)));
    xb = min(xb, c.cell[0] + static_cast<int>(floorf(c.frac[0] + rx)));
  }
  xa = max(xa, 0);
  xb = min(xb, static_cast<int>(view.xgrid.dims[0]) - 1);
  if (xa > xb) return false;
  const std::uint64_t row = static_cast<std::uint64_t>(jz) * g.dims[1] + jy;
  return table.range(row, view.xgrid.dims[0], xa, xb, s0, s1);
}

// Calls visit(q, dx, dy, dz, r2) for every candidate source q (a float4, w = original index) of
// the target p in slot t, self excluded: one thread per target, row after row. Self is excluded
// by splitting its own row's range around it, not by a test per candidate, and the walk is by
// pointer: the inner loop is a load and the distance.
template <class Table, class Visit>
__device__ __forceinline__ void for_each_candidate(const float4* __restrict__ pos, Slot t,
                                                   const float4& p, const GridView& view,
                                                   const Table& table, Visit&& visit) {
  const TargetCell c = locate(view, p);
  const int reach = view.grid.reach;
  const float4* const self = pos + t;
  const auto one = [&](const float4& v) {
    const float dx = v.x - p.x, dy = v.y - p.y, dz = v.z - p.z;
    visit(v, dx, dy, dz, squared_distance(dx, dy, dz));
  };
  // Four loads in flight, one 32-bit count per four (a 64-bit pointer compare costs more); not
  // unrolled further, which would leave more lanes waiting on the remainders.
  const auto scan = [&](const float4* q, const float4* last) {
#pragma unroll 1
    for (int fours = static_cast<int>(last - q) / 4; fours > 0; --fours, q += 4) {
      float4 v[4];
#pragma unroll
      for (int u = 0; u < 4; ++u) v[u] = __ldg(q + u);
#pragma unroll
      for (int u = 0; u < 4; ++u) one(v[u]);
    }
    for (; q < last; ++q) one(__ldg(q));
  };
  const auto scan_row = [&](Slot s0, Slot s1) {
    const float4 *first = pos + s0, *last = pos + s1;
    if (self >= first && self < last) {
      scan(first, self);
      scan(self + 1, last);
    } else {
      scan(first, last);
    }
  };
  for (int dz = -reach; dz <= reach; ++dz) {
    for (int dy = -reach; dy <= reach; ++dy) {
      Slot s0, s1;
      if (row_range(view, table, c, dz, dy, s0, s1)) scan_row(s0, s1);
    }
  }
}

// Calls on_pair(q, dx, dy, dz, r2) for every in-range source q of the target in slot t.
template <class Table, class OnPair>
__device__ __forceinline__ void for_each_pair(const float4* __restrict__ pos, Slot t,
                                              const float4& p, const GridView& view,
                                              const Table& table, float cutoff_squared,
                                              OnPair&& on_pair) {
  for_each_candidate(pos, t, p, view, table,
                     [&](const float4& q, float dx, float dy, float dz, float r2) {
                       if (in_range(r2, cutoff_squared)) on_pair(q, dx, dy, dz, r2);
                     });
}

// acc += the pair's terms when `in`, by selects rather than a branch: the body is a few
// instructions and some lane of a warp is in range at almost every step, so a branch only adds
// its own cost (beta = 32, p = 32: 0.589 against 0.610 ms). A kernel whose terms vanish at
// r2 = +inf gets that instead of a select per term. The SPH force, which loads the source's
// inputs, keeps the branch.
template <class K>
__device__ __forceinline__ void accumulate_if(bool in, const K& kernel, Accumulator& acc,
                                              std::uint32_t i, std::uint32_t j, float dx, float dy,
                                              float dz, float r2) {
  if constexpr (K::vanishes_at_infinity) {
    kernel(acc, i, j, dx, dy, dz, in ? r2 : CUDART_INF_F);
  } else if constexpr (std::is_same_v<K, SphForceKernel>) {
    if (in) kernel(acc, i, j, dx, dy, dz, r2);
  } else {
    Accumulator pair;
    kernel(pair, i, j, dx, dy, dz, r2);
    if constexpr (K::has_count) acc.count += in ? pair.count : 0u;
    if constexpr (K::has_energy) acc.energy += in ? pair.energy : 0.0f;
    if constexpr (K::has_force) {
      acc.fx += in ? pair.fx : 0.0f;
      acc.fy += in ? pair.fy : 0.0f;
      acc.fz += in ? pair.fz : 0.0f;
    }
  }
}

__device__ __forceinline__ std::uint32_t original_index(const float4& q) {
  return __float_as_uint(q.w);
}

template <int G>
__device__ __forceinline__ float group_sum(float v) {
#pragma unroll
  for (int offset = G / 2; offset > 0; offset /= 2) v += __shfl_xor_sync(0xffffffffu, v, offset);
  return v;
}

template <int G>
__device__ __forceinline__ std::uint32_t group_sum(std::uint32_t v) {
#pragma unroll
  for (int offset = G / 2; offset > 0; offset /= 2) v += __shfl_xor_sync(0xffffffffu, v, offset);
  return v;
}

// One thread per target.
template <bool ManyRegisters, class K, class Table>
__global__ void __launch_bounds__(block_size, ManyRegisters ? 1 : 0)
    thread_kernel(const float4* __restrict__ pos, Slot n, GridView view, Table table,
                  float cutoff_squared, K kernel, OutputView out) {
  const Slot t = blockIdx.x * block_size + threadIdx.x;
  if (t >= n) return;
  const float4 p = pos[t];
  Accumulator acc;
  const std::uint32_t i = original_index(p);
  for_each_candidate(pos, t, p, view, table,
                     [&](const float4& q, float dx, float dy, float dz, float r2) {
                       accumulate_if(in_range(r2, cutoff_squared), kernel, acc, i,
                                     original_index(q), dx, dy, dz, r2);
                     });
  out.store(i, acc, kernel);
}

constexpr int max_rows = 49;  // (2 reach + 1)^2 rows for reach <= 3

// G lanes per target, over the target's candidates flattened into one list: the lanes find the
// rows' ranges together (a block of rows each), a prefix sum over the group places them one after
// the other, then lane g takes candidates g, g + G, ... of the whole list. Every lane does the
// same work whatever the lengths of the rows, and neighbouring lanes read neighbouring sources.
// The G partial sums are added in a fixed butterfly order: results do not change between runs.
template <int G, class K, class Table>
__global__ void __launch_bounds__(block_size)
    group_kernel(const float4* __restrict__ pos, Slot n, GridView view, Table table,
                 float cutoff_squared, K kernel, OutputView out) {
  constexpr int groups = block_size / G;
  constexpr int rows_per_lane_max = (max_rows + G - 1) / G;
  __shared__ uint2 rows[groups][max_rows];  // (first slot - first flat index, end flat index)
  const int group = threadIdx.x / G, lane = threadIdx.x % G;
  const Slot t = static_cast<Slot>((blockIdx.x * std::uint64_t{block_size} + threadIdx.x) / G);
  const bool active = t < n;  // no early return: every lane takes part in the shuffles
  const float4 p = active ? pos[t] : make_float4(0, 0, 0, 0);
  const TargetCell c = locate(view, p);
  const int reach = view.grid.reach, side = 2 * reach + 1, row_count = side * side;
  const int rows_per_lane = (row_count + G - 1) / G;
  const int first_row = lane * rows_per_lane;

  Slot base[rows_per_lane_max], length[rows_per_lane_max];
  Slot total = 0;
#pragma unroll
  for (int k = 0; k < rows_per_lane_max; ++k) {
    const int r = first_row + k;
    Slot s0 = 0, s1 = 0;
    if (!(active && k < rows_per_lane && r < row_count &&
          row_range(view, table, c, r / side - reach, r % side - reach, s0, s1)))
      s0 = s1 = 0;
    base[k] = s0;
    length[k] = s1 - s0;
    total += length[k];
  }
  Slot inclusive = total;
#pragma unroll
  for (int offset = 1; offset < G; offset *= 2) {
    const Slot v = __shfl_up_sync(0xffffffffu, inclusive, offset, G);
    if (lane >= offset) inclusive += v;
  }
  const Slot group_total = __shfl_sync(0xffffffffu, inclusive, G - 1, G);
  Slot flat = inclusive - total;
#pragma unroll
  for (int k = 0; k < rows_per_lane_max; ++k) {
    const int r = first_row + k;
    if (k < rows_per_lane && r < row_count) {
      rows[group][r] = make_uint2(base[k] - flat, flat + length[k]);
      flat += length[k];
    }
  }
  __syncwarp();

  // Unrolled by U: the slots of U candidates first (the row walk only moves forward), then U
  // independent loads in flight, then the U tests.
  constexpr int U = 4;
  Accumulator acc;
  int r = 0;
  uint2 row = rows[group][0];
  for (Slot first = lane; first < group_total; first += U * G) {
    Slot s[U];
#pragma unroll
    for (int u = 0; u < U; ++u) {
      const Slot f = first + u * G;
      if (f < group_total) {
        while (f >= row.y) row = rows[group][++r];
        s[u] = row.x + f;
      } else {
        s[u] = t;  // a valid slot; skipped below
      }
    }
    float4 q[U];
#pragma unroll
    for (int u = 0; u < U; ++u) q[u] = pos[s[u]];
#pragma unroll
    for (int u = 0; u < U; ++u) {
      const float dx = q[u].x - p.x, dy = q[u].y - p.y, dz = q[u].z - p.z;
      const float r2 = squared_distance(dx, dy, dz);
      if (in_range(r2, cutoff_squared) && s[u] != t)
        kernel(acc, original_index(p), original_index(q[u]), dx, dy, dz, r2);
    }
  }
  if constexpr (K::has_count) acc.count = group_sum<G>(acc.count);
  if constexpr (K::has_energy) acc.energy = group_sum<G>(acc.energy);
  if constexpr (K::has_force) {
    acc.fx = group_sum<G>(acc.fx);
    acc.fy = group_sum<G>(acc.fy);
    acc.fz = group_sum<G>(acc.fz);
  }
  if (active && lane == 0) out.store(original_index(p), acc, kernel);
}

template <class Table>
__global__ void __launch_bounds__(block_size)
    count_kernel(const float4* __restrict__ pos, Slot n, GridView view, Table table,
                 float cutoff_squared, std::uint32_t* counts) {
  const Slot t = blockIdx.x * block_size + threadIdx.x;
  if (t >= n) return;
  const float4 p = pos[t];
  std::uint32_t c = 0;
  for_each_pair(pos, t, p, view, table, cutoff_squared,
                [&](const float4&, float, float, float, float) { ++c; });
  counts[original_index(p)] = c;
}

template <class Table>
__global__ void __launch_bounds__(block_size)
    fill_kernel(const float4* __restrict__ pos, Slot n, GridView view, Table table,
                float cutoff_squared, const std::uint64_t* offsets, std::uint32_t* indices) {
  const Slot t = blockIdx.x * block_size + threadIdx.x;
  if (t >= n) return;
  const float4 p = pos[t];
  std::uint64_t slot = offsets[original_index(p)];
  for_each_pair(
      pos, t, p, view, table, cutoff_squared,
      [&](const float4& q, float, float, float, float) { indices[slot++] = original_index(q); });
}

// ---- build kernels ------------------------------------------------------------------------------

template <class Key>
__global__ void keys_kernel(const float* __restrict__ xyz, Slot n, GridView view, Key* keys,
                            Slot* index) {
  const Slot i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i >= n) return;
  keys[i] = static_cast<Key>(cell_key(view, xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]));
  index[i] = i;
}

// Particle i as the compute reads it: a float4 with w = i.
__device__ __forceinline__ float4 particle(const float* __restrict__ xyz, Slot i) {
  return make_float4(xyz[3 * std::size_t{i}], xyz[3 * std::size_t{i} + 1],
                     xyz[3 * std::size_t{i} + 2], __uint_as_float(i));
}

__device__ __forceinline__ void gather_one(const float* __restrict__ xyz, const Slot* order, Slot s,
                                           float4* pos) {
  pos[s] = particle(xyz, order[s]);
}

// Counting sort, pass 1 for particle i: its cell key, counted in start[] by an atomic whose
// return value is a provisional rank within the cell (its order varies from run to run).
__device__ __forceinline__ void count_one(const float* __restrict__ xyz, Slot i,
                                          const GridView& view, std::uint32_t* keys,
                                          Slot* provisional, Slot* start) {
  const auto key =
      static_cast<std::uint32_t>(cell_key(view, xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]));
  keys[i] = key;
  provisional[i] = atomicAdd(&start[key], 1u);
}

// Counting sort, pass 4 for particle i of the cell whose particles are members[first, last): its
// slot is first plus the number of them with a smaller index, exactly the layout of a stable sort
// by cell, so every sum is the same from run to run.
__device__ __forceinline__ void place_one(const float* __restrict__ xyz, const Slot* members,
                                          Slot first, Slot last, Slot i, float4* pos) {
  Slot rank = 0;
  for (Slot s = first; s < last; ++s) rank += members[s] < i;
  pos[first + rank] = particle(xyz, i);
}

// Dense, after a radix sort: the end of each cell's run, at entry key + 1 of start[] (zeroed,
// cells + 1 entries), and the gather. A prefix maximum then gives start[c] = the number of
// particles in cells below c, empty cells included: no search, no atomics.
__global__ void run_ends_kernel(const float* __restrict__ xyz, const std::uint32_t* keys,
                                const Slot* order, Slot n, Slot* start, float4* pos) {
  const Slot s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s >= n) return;
  if (s + 1 == n || keys[s] != keys[s + 1]) start[keys[s] + 1] = s + 1;
  gather_one(xyz, order, s, pos);
}

// Dense, counting sort. Pass 1: each particle's cell, counted in start[] (zeroed, cells + 1
// entries); pass 4 removes the order of the atomics.
__global__ void count_cells_kernel(const float* __restrict__ xyz, Slot n, GridView view,
                                   std::uint32_t* keys, Slot* provisional, Slot* start) {
  const Slot i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) count_one(xyz, i, view, keys, provisional, start);
}

// Dense, small inputs: the counting sort of passes 1 to 4 (count_cells_kernel .. place_kernel) in
// one block, one launch instead of six: launches, not work, are the cost up to 4096 particles
// (0.027 against 0.049 ms; at 16384 the one block is the slower, 0.098 against 0.052). The scan
// gives each thread a run of consecutive cells.
__global__ void __launch_bounds__(small_build_block)
    small_dense_build_kernel(const float* __restrict__ xyz, Slot n, GridView view,
                             std::uint32_t cells, std::uint32_t* keys, Slot* provisional,
                             Slot* members, Slot* start, float4* pos) {
  using Scan = cub::BlockScan<Slot, small_build_block>;
  __shared__ typename Scan::TempStorage scan_temp;
  const Slot entries = cells + 1;
  for (Slot c = threadIdx.x; c < entries; c += small_build_block) start[c] = 0;
  __syncthreads();
  for (Slot i = threadIdx.x; i < n; i += small_build_block)
    count_one(xyz, i, view, keys, provisional, start);
  __syncthreads();
  const Slot per_thread = (entries + small_build_block - 1) / small_build_block;
  const Slot first = threadIdx.x * per_thread, last = min(first + per_thread, entries);
  Slot sum = 0;
  for (Slot c = first; c < last; ++c) sum += start[c];
  Slot offset;
  Scan(scan_temp).ExclusiveSum(sum, offset);
  for (Slot c = first; c < last; ++c) {
    const Slot count = start[c];
    start[c] = offset;
    offset += count;
  }
  __syncthreads();
  for (Slot i = threadIdx.x; i < n; i += small_build_block)
    members[start[keys[i]] + provisional[i]] = i;
  __syncthreads();
  for (Slot i = threadIdx.x; i < n; i += small_build_block)
    place_one(xyz, members, start[keys[i]], start[keys[i] + 1], i, pos);
}

// Pass 2 is an exclusive scan of start[] in place. Pass 3: the particles of each cell, in the
// provisional order.
__global__ void scatter_cells_kernel(const std::uint32_t* keys, const Slot* provisional,
                                     const Slot* start, Slot n, Slot* members) {
  const Slot i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) members[start[keys[i]] + provisional[i]] = i;
}

// Pass 4, by particle (place_one). The scan of the cell costs less than the compute's own scan of
// it (every target tests every particle of its own cell).
__global__ void place_kernel(const float* __restrict__ xyz, const std::uint32_t* keys,
                             const Slot* start, const Slot* members, Slot n, float4* pos) {
  const Slot i = blockIdx.x * blockDim.x + threadIdx.x;
  if (i < n) place_one(xyz, members, start[keys[i]], start[keys[i] + 1], i, pos);
}

// Pass 4, by cell: a thread per cell lists its particles by index (a rank per particle among the
// cell's few) and writes them to the cell's consecutive slots: the writes are coalesced and each
// particle's position is read once, where place_kernel reads the table at random per particle
// and writes at random. Cells of more than `warp_cell_from` particles are ranked by the whole
// warp together, one cell after another (a cluster would leave one thread with m^2 steps).
constexpr Slot warp_cell_from = 32;
__global__ void place_by_cell_kernel(const float* __restrict__ xyz, const Slot* start,
                                     const Slot* members, std::uint32_t cells, float4* pos) {
  const std::uint32_t c = blockIdx.x * blockDim.x + threadIdx.x;
  const int lane = threadIdx.x % 32;
  Slot first = 0, last = 0;
  if (c < cells) {
    first = start[c];
    last = start[c + 1];
  }
  const bool large = last - first > warp_cell_from;
  if (!large)
    for (Slot s = first; s < last; ++s) place_one(xyz, members, first, last, members[s], pos);
  for (unsigned ballot = __ballot_sync(0xffffffffu, large); ballot != 0; ballot &= ballot - 1) {
    const int owner = __ffs(ballot) - 1;
    const Slot f = __shfl_sync(0xffffffffu, first, owner),
               l = __shfl_sync(0xffffffffu, last, owner);
    for (Slot s = f + lane; s < l; s += 32) place_one(xyz, members, f, l, members[s], pos);
  }
}

__global__ void gather_kernel(const float* __restrict__ xyz, const Slot* order, Slot n,
                              float4* pos) {
  const Slot s = blockIdx.x * blockDim.x + threadIdx.x;
  if (s < n) gather_one(xyz, order, s, pos);
}

struct IsCellHead {
  const std::uint64_t* keys;
  __host__ __device__ bool operator()(Slot s) const { return s == 0 || keys[s] != keys[s - 1]; }
};

// Compact, pass 1: unique keys, the final start entry, and each row's first unique cell.
__global__ void insert_rows_kernel(const std::uint64_t* keys, const Slot* run_start,
                                   const std::uint32_t* runs_ptr, Slot n, std::uint32_t dims0,
                                   std::uint64_t* cell_keys, Slot* cell_start,
                                   std::uint64_t* row_keys, uint2* row_cells, std::uint64_t mask,
                                   int shift) {
  const std::uint32_t runs = *runs_ptr;
  const std::uint32_t u = blockIdx.x * blockDim.x + threadIdx.x;
  if (u >= runs) return;
  const std::uint64_t key = keys[run_start[u]];
  cell_keys[u] = key;
  cell_start[u] = run_start[u];
  if (u == runs - 1) cell_start[runs] = n;
  const std::uint64_t row = key / dims0;
  if (u > 0 && keys[run_start[u - 1]] / dims0 == row) return;
  std::uint64_t h = row_hash(row, shift);
  for (;;) {
    const unsigned long long old =
        atomicCAS(reinterpret_cast<unsigned long long*>(&row_keys[h]),
                  static_cast<unsigned long long>(empty_row), static_cast<unsigned long long>(row));
    if (old == empty_row) {
      row_cells[h].x = u;
      return;
    }
    h = (h + 1) & mask;
  }
}

// Compact, pass 2: each row's end, written by the row's last unique cell.
__global__ void close_rows_kernel(const std::uint64_t* cell_keys, const std::uint32_t* runs_ptr,
                                  std::uint32_t dims0, const std::uint64_t* row_keys,
                                  uint2* row_cells, std::uint64_t mask, int shift) {
  const std::uint32_t runs = *runs_ptr;
  const std::uint32_t u = blockIdx.x * blockDim.x + threadIdx.x;
  if (u >= runs) return;
  const std::uint64_t row = cell_keys[u] / dims0;
  if (u + 1 < runs && cell_keys[u + 1] / dims0 == row) return;
  std::uint64_t h = row_hash(row, shift);
  while (row_keys[h] != row) h = (h + 1) & mask;
  row_cells[h].y = u + 1;
}

// Bits needed to hold every value below `count` (at least 1), and powers of two (no C++20 <bit>
// in CUDA translation units, which compile as C++17).
int key_bits(std::uint64_t count) {
  int bits = 1;
  while (bits < 64 && (count - 1) >> bits) ++bits;
  return bits;
}
std::uint64_t power_of_two_at_least(std::uint64_t v) {
  std::uint64_t p = 1;
  while (p < v) p <<= 1;
  return p;
}
int log2_of_power_of_two(std::uint64_t p) {
  int l = 0;
  while ((std::uint64_t{1} << l) < p) ++l;
  return l;
}

unsigned blocks_for(std::uint64_t count, int threads = block_size) {
  return static_cast<unsigned>((count + threads - 1) / threads);
}

// ---- the method
// -----------------------------------------------------------------------------------

class Grid final : public GpuMethod {
 public:
  explicit Grid(const GridOptions& options) : options_(options) {}
  ~Grid() override {
    if (runs_host_) cudaFreeHost(runs_host_);
  }

  void build(const float* xyz, std::size_t n, float cutoff) override {
    if (n >= UINT32_MAX)
      throw Error(ErrorCode::invalid_argument,
                  "grid handles at most 2^32 - 2 particles, got " + std::to_string(n));
    n_ = static_cast<Slot>(n);
    cutoff_squared_ = squared_cutoff(cutoff);
    build_timer_.start();
    float lo[3], hi[3];
    box_.compute(xyz, n, lo, hi);
    choose_grid(lo, hi, cutoff);
    if (dense_)
      build_dense(xyz);
    else
      build_compact(xyz);
    build_timer_.stop();
    choose_lanes();
  }

  void compute(Kernel kernel, const KernelOptions& options) override {
    timed_compute(kernel, n_, [&](const OutputView& out) {
      with_kernel(kernel, options, cutoff_squared_, [&](auto k) {
        with_table([&](const auto& table) {
          switch (lanes_) {
            case 1:
              if (many_registers_)
                thread_kernel<true><<<blocks_for(n_), block_size>>>(pos_.data(), n_, view_, table,
                                                                    cutoff_squared_, k, out);
              else
                thread_kernel<false><<<blocks_for(n_), block_size>>>(pos_.data(), n_, view_, table,
                                                                     cutoff_squared_, k, out);
              break;
            case 4:
              launch_group<4>(table, k, out);
              break;
            case 8:
              launch_group<8>(table, k, out);
              break;
            case 16:
              launch_group<16>(table, k, out);
              break;
            default:
              launch_group<32>(table, k, out);
              break;
          }
        });
      });
    });
  }

  NeighbourList neighbours() override {
    return build_neighbour_list(
        n_,
        [&](std::uint32_t* counts) {
          with_table([&](const auto& table) {
            count_kernel<<<blocks_for(n_), block_size>>>(pos_.data(), n_, view_, table,
                                                         cutoff_squared_, counts);
          });
          RAYCUT_CUDA_CHECK_LAUNCH();
        },
        [&](const std::uint64_t* offsets, std::uint32_t* indices) {
          with_table([&](const auto& table) {
            fill_kernel<<<blocks_for(n_), block_size>>>(pos_.data(), n_, view_, table,
                                                        cutoff_squared_, offsets, indices);
          });
          RAYCUT_CUDA_CHECK_LAUNCH();
        });
  }

 private:
  template <int G, class Table, class K>
  void launch_group(const Table& table, K k, const OutputView& out) {
    group_kernel<G><<<blocks_for(std::uint64_t{n_} * G), block_size>>>(
        pos_.data(), n_, view_, table, cutoff_squared_, k, out);
  }

  template <class F>
  void with_table(F&& f) const {
    if (dense_)
      f(DenseTable{start_.data()});
    else
      f(CompactTable{cell_keys_.data(), start_.data(), row_keys_.data(), row_cells_.data(),
                     row_mask_, row_shift_});
  }

  void choose_grid(const float lo[3], const float hi[3], float cutoff) {
    int k = options_.cells_per_cutoff;
    const CellGrid coarse = make_cell_grid(lo, hi, cutoff, 1);
    const double density = static_cast<double>(n_) / static_cast<double>(coarse.cell_count());
    if (k <= 0) k = density >= fine_cells_density ? 2 : 1;
    many_registers_ = options_.thread_registers == 2 ||
                      (options_.thread_registers == 0 && density >= many_registers_density);
    grid_ = make_cell_grid(lo, hi, cutoff, k);
    view_.grid = grid_;
    // Narrower x cells, unless they alone would push a dense table over 8 cells per particle
    // (a sphere surface at alpha = 64: x cells C wide, 19 cells per particle: 0.127 ms; C/2 wide,
    // 38 per particle: 0.148 ms) or the table would be compact anyway.
    int split = options_.x_split > 0 ? options_.x_split : default_x_split[std::min(k, 2)];
    for (;; split /= 2) {
      view_.xgrid = split > 1 ? make_cell_grid(lo, hi, cutoff, k * split) : grid_;
      if (split == 1 || options_.x_split > 0 || options_.layout != 0 || few_cells(cell_count()) ||
          !fits_dense(grid_.cell_count()))
        break;
    }
    view_.x_cells_per_cell = static_cast<float>(grid_.width * view_.xgrid.inverse_width);
    const std::uint64_t cells = cell_count();
    dense_ = options_.layout == 1 ? cells <= (1ull << 31)
                                  : (options_.layout == 2 ? false : fits_dense(cells));
    // Slack: relative 1e-5 and absolute 1e-5 cell, far above the float round-off of the
    // predicate (~2e-7 relative) and of the cell fractions (~1e-7 cell).
    view_.reach_cells = static_cast<float>(cutoff * grid_.inverse_width * (1.0 + 1e-5) + 1e-5);
    view_.cull = options_.cull;
  }

  // The dense table: up to 8 cells per particle (32 bytes), or up to 64 while the table stays
  // within 64 MiB (a sphere surface at alpha = 64: dense 0.15 ms, compact 0.22 ms; at alpha = 128,
  // 0.9 GB of table, compact wins 2x). Memory stays O(N) plus a constant.
  bool fits_dense(std::uint64_t cells) const {
    return few_cells(cells) || (cells <= 64ull * n_ && cells <= dense_cells_any_n);
  }
  // At most 8 cells per particle (plus a constant for tiny N): a dense table of <= 32 bytes each.
  bool few_cells(std::uint64_t cells) const { return cells <= 8ull * n_ + 4096; }

  // Lanes per target (see thread_kernel_from).
  void choose_lanes() {
    if (grid_.reach > 3) {  // the group kernel's row table holds (2 * 3 + 1)^2 rows
      lanes_ = 1;
      return;
    }
    if (options_.lanes_per_target > 0) {
      lanes_ = options_.lanes_per_target;
      return;
    }
    lanes_ = n_ >= thread_kernel_from ? 1 : (n_ <= group_of_32_up_to ? 32 : 16);
  }

  // Radix sort of (key, index) on the bits the keys use; returns the sorted buffers.
  template <class Key>
  void sort(DeviceBuffer<Key>& keys, DeviceBuffer<Key>& keys_alt, int bits, Key*& sorted_keys) {
    cub::DoubleBuffer<Key> k(keys.data(), keys_alt.data());
    cub::DoubleBuffer<Slot> v(index_.data(), index_alt_.data());
    // The temporary size depends on (n, bits, key size) only: ask cub again only when they change.
    const std::uint64_t shape = (std::uint64_t{n_} << 16) | (bits << 4) | sizeof(Key);
    if (shape != sort_shape_) {
      RAYCUT_CUDA_CHECK(
          cub::DeviceRadixSort::SortPairs(nullptr, sort_temp_bytes_, k, v, n_, 0, bits));
      sort_shape_ = shape;
    }
    std::size_t temp_bytes = sort_temp_bytes_;
    temp_.resize(std::max<std::size_t>(temp_bytes, 1));
    RAYCUT_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(temp_.data(), temp_bytes, k, v, n_, 0, bits));
    sorted_keys = k.Current();
    order_ = v.Current();
  }

  std::uint64_t cell_count() const {
    return std::uint64_t{view_.xgrid.dims[0]} * grid_.dims[1] * grid_.dims[2];
  }

  void build_dense(const float* xyz) {
    const std::uint64_t cells = cell_count();
    keys32_.resize(n_);
    index_.resize(n_);
    index_alt_.resize(n_);
    pos_.resize(n_);
    start_.resize(cells + 1);
    const bool small = n_ <= small_build_up_to && cells + 1 <= small_build_cells;
    if (options_.dense_build == 3 || (options_.dense_build == 0 && small)) {
      small_dense_build_kernel<<<1, small_build_block>>>(
          xyz, n_, view_, static_cast<std::uint32_t>(cells), keys32_.data(), index_.data(),
          index_alt_.data(), start_.data(), pos_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
      return;
    }
    RAYCUT_CUDA_CHECK(cudaMemsetAsync(start_.data(), 0, (cells + 1) * sizeof(Slot)));
    // One or two particles per cell: placed cell by cell (more per cell would serialise a
    // thread's cell; more cells than particles would spend threads on empty ones).
    const bool by_cell =
        options_.dense_build == 4 || (options_.dense_build == 0 && cells <= n_ && 2 * cells >= n_);
    const std::size_t counting_limit = by_cell ? counting_sort_up_to : counting_sort_up_to - 1;
    const bool radix =
        options_.dense_build == 2 || (options_.dense_build == 0 && n_ > counting_limit);
    if (radix) {
      keys32_alt_.resize(n_);
      keys_kernel<<<blocks_for(n_, 256), 256>>>(xyz, n_, view_, keys32_.data(), index_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
      std::uint32_t* sorted = nullptr;
      sort(keys32_, keys32_alt_, key_bits(cells), sorted);
      run_ends_kernel<<<blocks_for(n_, 256), 256>>>(xyz, sorted, order_, n_, start_.data(),
                                                    pos_.data());
      RAYCUT_CUDA_CHECK_LAUNCH();
      scan(::cuda::maximum<Slot>{}, cells + 1);
      return;
    }
    // Counting sort: no radix passes, no table search; its atomics lose to the sort's streaming
    // at large N.
    count_cells_kernel<<<blocks_for(n_, 256), 256>>>(xyz, n_, view_, keys32_.data(), index_.data(),
                                                     start_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    scan(::cuda::std::plus<Slot>{}, cells + 1, /*exclusive=*/true);
    scatter_cells_kernel<<<blocks_for(n_, 256), 256>>>(keys32_.data(), index_.data(), start_.data(),
                                                       n_, index_alt_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    if (by_cell)
      place_by_cell_kernel<<<blocks_for(cells, 256), 256>>>(
          xyz, start_.data(), index_alt_.data(), static_cast<std::uint32_t>(cells), pos_.data());
    else
      place_kernel<<<blocks_for(n_, 256), 256>>>(xyz, keys32_.data(), start_.data(),
                                                 index_alt_.data(), n_, pos_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
  }

  // start_[0, count) scanned in place with op (inclusive, or exclusive from 0).
  template <class Op>
  void scan(Op op, std::uint64_t count, bool exclusive = false) {
    const auto run = [&](void* temp, std::size_t& bytes) {
      return exclusive ? cub::DeviceScan::ExclusiveScan(temp, bytes, start_.data(), start_.data(),
                                                        op, Slot{0}, count)
                       : cub::DeviceScan::InclusiveScan(temp, bytes, start_.data(), start_.data(),
                                                        op, count);
    };
    // The temporary size depends on the length and the kind of scan only: ask cub again only
    // when they change.
    const std::uint64_t shape = (count << 1) | (exclusive ? 1 : 0);
    if (shape != scan_shape_) {
      RAYCUT_CUDA_CHECK(run(nullptr, scan_temp_bytes_));
      scan_shape_ = shape;
    }
    std::size_t temp_bytes = scan_temp_bytes_;
    temp_.resize(std::max<std::size_t>(temp_bytes, 1));
    RAYCUT_CUDA_CHECK(run(temp_.data(), temp_bytes));
  }

  void build_compact(const float* xyz) {
    keys64_.resize(n_);
    keys64_alt_.resize(n_);
    index_.resize(n_);
    index_alt_.resize(n_);
    pos_.resize(n_);
    run_start_.resize(n_);
    keys_kernel<<<blocks_for(n_, 256), 256>>>(xyz, n_, view_, keys64_.data(), index_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();
    std::uint64_t* sorted = nullptr;
    sort(keys64_, keys64_alt_, key_bits(cell_count()), sorted);
    gather_kernel<<<blocks_for(n_, 256), 256>>>(xyz, order_, n_, pos_.data());
    RAYCUT_CUDA_CHECK_LAUNCH();

    // First slot of every non-empty cell; the number of cells comes back to size the tables.
    if (!runs_host_) {
      RAYCUT_CUDA_CHECK(cudaHostAlloc(reinterpret_cast<void**>(&runs_host_), sizeof(std::uint32_t),
                                      cudaHostAllocMapped));
      RAYCUT_CUDA_CHECK(
          cudaHostGetDevicePointer(reinterpret_cast<void**>(&runs_device_), runs_host_, 0));
    }
    std::uint32_t* runs_device = runs_device_;
    const thrust::counting_iterator<Slot> slots(0);
    std::size_t temp_bytes = 0;
    RAYCUT_CUDA_CHECK(cub::DeviceSelect::If(nullptr, temp_bytes, slots, run_start_.data(),
                                            runs_device, n_, IsCellHead{sorted}));
    temp_.resize(std::max<std::size_t>(temp_bytes, 1));
    RAYCUT_CUDA_CHECK(cub::DeviceSelect::If(temp_.data(), temp_bytes, slots, run_start_.data(),
                                            runs_device, n_, IsCellHead{sorted}));
    RAYCUT_CUDA_CHECK(cudaStreamSynchronize(nullptr));
    const std::uint32_t runs = *runs_host_;

    cell_keys_.resize(runs);
    start_.resize(runs + 1);
    const std::uint64_t capacity =
        power_of_two_at_least(std::max<std::uint64_t>(2ull * runs, 1024));
    row_keys_.resize(capacity);
    row_cells_.resize(capacity);
    row_mask_ = capacity - 1;
    row_shift_ = 64 - log2_of_power_of_two(capacity);
    RAYCUT_CUDA_CHECK(cudaMemsetAsync(row_keys_.data(), 0xFF, capacity * sizeof(std::uint64_t)));
    insert_rows_kernel<<<blocks_for(runs, 256), 256>>>(
        sorted, run_start_.data(), runs_device, n_, view_.xgrid.dims[0], cell_keys_.data(),
        start_.data(), row_keys_.data(), row_cells_.data(), row_mask_, row_shift_);
    RAYCUT_CUDA_CHECK_LAUNCH();
    close_rows_kernel<<<blocks_for(runs, 256), 256>>>(cell_keys_.data(), runs_device,
                                                      view_.xgrid.dims[0], row_keys_.data(),
                                                      row_cells_.data(), row_mask_, row_shift_);
    RAYCUT_CUDA_CHECK_LAUNCH();
  }

  GridOptions options_;
  Slot n_ = 0;
  float cutoff_squared_ = 0;
  int lanes_ = 1;
  bool many_registers_ = false;  // thread kernel: see many_registers_density
  CellGrid grid_;
  GridView view_{};
  bool dense_ = true;
  BoundingBox box_;
  DeviceBuffer<std::uint32_t> keys32_, keys32_alt_;
  DeviceBuffer<std::uint64_t> keys64_, keys64_alt_;
  DeviceBuffer<Slot> index_, index_alt_, run_start_;
  Slot* order_ = nullptr;  // index_ or index_alt_: sorted slot -> original index
  DeviceBuffer<float4> pos_;
  DeviceBuffer<Slot> start_;  // dense: per cell; compact: per non-empty cell
  DeviceBuffer<std::uint64_t> cell_keys_, row_keys_;
  DeviceBuffer<uint2> row_cells_;
  std::uint64_t row_mask_ = 0;
  int row_shift_ = 0;
  std::uint32_t* runs_host_ = nullptr;  // mapped pinned memory
  std::uint32_t* runs_device_ = nullptr;
  DeviceBuffer<unsigned char> temp_;
  std::uint64_t sort_shape_ = 0, scan_shape_ = 0;
  std::size_t sort_temp_bytes_ = 0, scan_temp_bytes_ = 0;
};

}  // namespace

std::unique_ptr<Method> make_grid_with(const GridOptions& options) {
  return std::make_unique<Grid>(options);
}
std::unique_ptr<Method> make_grid() {
  return make_grid_with(GridOptions{});
}

}  // namespace raycut::detail::cuda
