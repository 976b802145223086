// The production grid's traversal (the table it walks is built by src/cuda/grid_build.cu): for
// every target, the (2k+1)^2 rows of cells around it, rows out of reach of its actual position
// skipped and each row trimmed to the x cells its sphere can touch, leaving one contiguous range
// of float4 per row. Large inputs run a thread per target; small ones let 4-32 lanes share each
// target so that they still fill the GPU. Culling is conservative by construction (slack far
// above float round-off); the shared predicate decides every pair (in_range_of: with images,
// the float band in double, the cells then as wide as its reach); self is excluded by slot.
// Every functor runs through run_grid(): counting, list filling, the built-in kernels and the
// caller's own. A half list whose rows may follow the traversal (ListOptions::any_row) walks
// half the stencil (StencilRows). docs/grid.md has the measurements behind each choice. nvcc
// only.
#pragma once

#include <cuda_runtime.h>

#include <algorithm>
#include <cstdint>
#include <cstdlib>
#include <type_traits>

#include "raycut/detail/cuda/visit.cuh"
#include "raycut/detail/pair_pass.hpp"

namespace raycut::detail::cuda {

using Slot = std::uint32_t;
constexpr int grid_block_size = 128;
constexpr std::uint64_t empty_row = ~std::uint64_t{0};

struct DenseTable {
  const Slot* start;
  // Possibly empty (s0 == s1): the scan then does nothing.
  __device__ __forceinline__ bool range(std::uint64_t row, std::uint32_t dims0, std::uint32_t xa,
                                        std::uint32_t xb, Slot& s0, Slot& s1) const {
    const std::uint64_t base = row * dims0;
    s0 = start[base + xa];
    s1 = start[base + xb + 1];
    return true;
  }
};

__host__ __device__ __forceinline__ std::uint64_t row_hash(std::uint64_t row, int shift) {
  return (row * 0x9E3779B97F4A7C15ull) >> shift;
}

struct CompactTable {
  CompactTablePass t;

  __device__ __forceinline__ bool range(std::uint64_t row, std::uint32_t dims0, std::uint32_t xa,
                                        std::uint32_t xb, Slot& s0, Slot& s1) const {
    std::uint64_t h = row_hash(row, t.shift);
    uint2 cells;
    for (;;) {
      const std::uint64_t k = t.row_keys[h];
      if (k == row) {
        cells = reinterpret_cast<const uint2*>(t.row_cells)[h];
        break;
      }
      if (k == empty_row) return false;
      h = (h + 1) & t.mask;
    }
    const std::uint64_t base = row * dims0;
    const std::uint32_t lo = lower_bound(cells.x, cells.y, base + xa);
    const std::uint32_t hi = lower_bound(lo, cells.y, base + xb + 1);
    if (lo == hi) return false;
    s0 = t.cell_start[lo];
    s1 = t.cell_start[hi];
    return true;
  }

  __device__ __forceinline__ std::uint32_t lower_bound(std::uint32_t first, std::uint32_t last,
                                                       std::uint64_t key) const {
    while (first < last) {
      const std::uint32_t mid = first + (last - first) / 2;
      if (t.cell_keys[mid] < key)
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

// The z cell of point k at height z: within its system's layer of z cells (batches).
__host__ __device__ __forceinline__ std::uint32_t z_cell(const GridGeometry& view, float z,
                                                         std::uint32_t k) {
  const std::uint32_t c = view.grid.coord(z, 2);
  if (view.layer_cells == 0) return c;
  const std::uint32_t last = view.layer_cells - 1;
  return view.system[k] * view.layer_stride + (c < last ? c : last);
}

__device__ __forceinline__ TargetCell locate(const GridGeometry& view, const float4& p) {
  TargetCell c;
  const float pc[3] = {p.x, p.y, p.z};
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    const CellGrid& g = a == 0 ? view.xgrid : view.grid;
    c.cell[a] =
        static_cast<int>(a == 2 ? z_cell(view, pc[a], __float_as_uint(p.w)) : g.coord(pc[a], a));
    const int own = a == 2 ? static_cast<int>(g.coord(pc[a], a)) : c.cell[a];
    c.frac[a] =
        static_cast<float>((static_cast<double>(pc[a]) - g.origin[a]) * g.inverse_width - own);
  }
  return c;
}

// Row-major key of the cell holding point k at (x, y, z): the x cells of a row are consecutive
// keys.
__host__ __device__ __forceinline__ std::uint64_t cell_key(const GridGeometry& view, float x,
                                                           float y, float z, std::uint32_t k) {
  const CellGrid& g = view.grid;
  return (static_cast<std::uint64_t>(z_cell(view, z, k)) * g.dims[1] + g.coord(y, 1)) *
             view.xgrid.dims[0] +
         view.xgrid.coord(x, 0);
}

// The slots [s0, s1) of row (dz, dy) around the target, trimmed in x to the cells its sphere
// can reach; false when the row is outside the grid or out of reach (an empty row may come back
// as s0 == s1). half (StencilRows): only the slots after the target's own, t.
template <class Table>
__device__ __forceinline__ bool row_range(const GridGeometry& view, const Table& table,
                                          const TargetCell& c, int dz, int dy, bool half, Slot t,
                                          Slot& s0, Slot& s1) {
  const bool own_row = dz == 0 && dy == 0;
  if (half && (dz < 0 || (dz == 0 && dy < 0))) return false;
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
  xa = max(xa, half && own_row ? c.cell[0] : 0);
  xb = min(xb, static_cast<int>(view.xgrid.dims[0]) - 1);
  if (xa > xb) return false;
  const std::uint64_t row = static_cast<std::uint64_t>(jz) * g.dims[1] + jy;
  if (!table.range(row, view.xgrid.dims[0], xa, xb, s0, s1)) return false;
  if (half && own_row) s0 = min(max(s0, t + 1), s1);
  return true;
}

__device__ __forceinline__ std::uint32_t original_index(const float4& q) {
  return __float_as_uint(q.w);
}

// A half list by the half stencil (ListOptions::any_row): a pair of two home points (points
// [0, targets): the particles themselves) is taken from its lower slot. The slots are in cell
// order, so the later slots are the rows (dz, dy) after (0, 0) and the own row after the
// target's own slot: 13 of the 26 neighbour cells and half of its own, half the candidates. An
// image point is never a target, so a pair across the box is met from both of its particles and
// the list's own rule (i < j, or i == j and S positive) keeps one: a particle with images walks
// every row (about one in eight of a 2^20 liquid). One without has no image point within its
// reach (an image within C of it would put it within C of a face, and give it an image), so the
// rows before its own hold nothing it takes.
struct StencilRows {
  Slot targets = 0;
  const std::uint32_t* image_counts = nullptr;  // by source; null: no images
  // Whether target point i walks only the later slots.
  __device__ __forceinline__ bool half_rows(std::uint32_t i) const {
    return !(image_counts && image_counts[i] > 0);
  }
  // Whether candidate point k, at slot s of target slot t, may be taken: a home pair from its
  // lower slot only.
  __device__ __forceinline__ bool allows(std::uint32_t k, Slot s, Slot t) const {
    return k >= targets || s > t;
  }
  __device__ __forceinline__ bool home(std::uint32_t k) const { return k < targets; }
};

// The stencil of every functor that never asks for the half one (has_any_row false), and of
// lists that do not: its checks fold away at compile time. (A runtime flag tested in every
// kernel made the full-stencil passes 1.1-1.4x slower on an H100: docs/grid.md.)
struct FullStencil {
  __device__ __forceinline__ bool half_rows(std::uint32_t) const { return false; }
  __device__ __forceinline__ bool allows(std::uint32_t, Slot, Slot) const { return true; }
  __device__ __forceinline__ bool home(std::uint32_t) const { return false; }
};

// Candidate point k at slot s of target i through f (visit), as the half stencil has it: a home
// pair, decided by its slots, is not halved again by index; and where the call reads neither j
// nor S (a list's count without per-pair cutoffs) it is taken without the image table's 16-byte
// read (a home point is its own source: j = k).
template <class F, class Images, class Stencil>
__device__ __forceinline__ void visit_stencil(const F& f, typename F::Accumulator& acc, bool in,
                                              std::uint32_t i, std::uint32_t k, Slot s, Vec3 r,
                                              float r2, const Images& images,
                                              const typename Images::Target& ti,
                                              const Stencil& stencil) {
  if constexpr (has_any_row<F>::value && std::is_same_v<Stencil, StencilRows>) {
    const bool home = stencil.home(k);
    const F g = for_candidate(f, home);
    if constexpr (!emits_entries<F>::value) {
      if (home && !f.cutoffs.active()) {
        if (in) apply(g, acc, i, k, r, r2);
        return;
      }
    }
    visit(g, acc, in, i, k, s, r, r2, images, ti);
  } else {
    (void)stencil;
    visit(f, acc, in, i, k, s, r, r2, images, ti);
  }
}

// Calls visit(q, slot, r, r2) for every candidate source q (a float4, w = point index) of the
// target p in slot t, self excluded: one thread per target, row after row. Self is excluded by
// splitting its own row's range around it, not by a test per candidate, and the walk is by
// pointer: the inner loop is a load and the distance.
template <class Table, class Visit>
__device__ __forceinline__ void for_each_candidate(const float4* __restrict__ pos, Slot t,
                                                   const float4& p, const GridGeometry& view,
                                                   const Table& table, bool half, Visit&& visit) {
  const TargetCell c = locate(view, p);
  const int reach = view.grid.reach;
  const float4* const self = pos + t;
  const auto one = [&](const float4& v, const float4* at) {
    const Vec3 r{v.x - p.x, v.y - p.y, v.z - p.z};
    visit(v, static_cast<Slot>(at - pos), r, squared_distance(r.x, r.y, r.z));
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
      for (int u = 0; u < 4; ++u) one(v[u], q + u);
    }
    for (; q < last; ++q) one(__ldg(q), q);
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
      if (row_range(view, table, c, dz, dy, half, t, s0, s1)) scan_row(s0, s1);
    }
  }
}

// The float band, deferred (docs/grid.md, "Registers"). With images the predicate decides the
// few pairs of the float band in double (in_range_of), and inlined into a traversal that double
// arithmetic doubles its registers (32-56 to 64-128) and halves its warps. So for a functor that
// allows it (option::repeatable), the traversal decides in float only the pairs outside the band
// and notes whether a candidate fell in it; such a target is left unfinished, its slot listed,
// and grid_band_kernel, a second launch, computes it whole with the exact predicate.
template <class F>
inline constexpr bool defers_band = repeatable<F>::value;

// RAYCUT_GRID_INLINE_BAND=1: every pass decides the band inline, as a functor without the option
// does (for measuring one against the other in one process: docs/grid.md, "Registers").
inline bool band_inline_requested() {
  static const bool inline_band = [] {
    const char* v = std::getenv("RAYCUT_GRID_INLINE_BAND");
    return v != nullptr && v[0] == '1';
  }();
  return inline_band;
}

struct BandTargets {
  Slot* list;  // list[0]: how many; then their slots
  __device__ __forceinline__ void add(Slot t) const { list[1 + atomicAdd(list, 1u)] = t; }
};

// in_range_of, or with Defer the float decision outside the band, `band` set for a candidate in
// it (then out here: its target is computed again).
template <bool Defer, class Images>
__device__ __forceinline__ bool in_range_or_band(const Images& images, float cutoff_squared,
                                                 std::uint32_t i, std::uint32_t k, Vec3& r,
                                                 float& r2, bool& band) {
  if constexpr (Defer) {
    const bool in = r2 < images.exact.float_in;
    band |= !in && r2 < images.exact.float_out;
    return in;
  } else {
    return in_range_of(images, cutoff_squared, i, k, r, r2);
  }
}

// Target t of a thread's own: every candidate through f; false (and nothing finished) when
// Defer found a candidate in the band.
template <bool Defer, class F, class Table, class Images, class Stencil>
__device__ __forceinline__ bool grid_thread_target(const float4* __restrict__ pos, Slot t,
                                                   const GridGeometry& view, const Table& table,
                                                   float cutoff_squared, const F& f,
                                                   const Images& images, const Stencil& stencil) {
  const float4 p = pos[t];
  const std::uint32_t i = original_index(p);
  const typename Images::Target ti = images.target(t);
  typename F::Accumulator acc = initial_state(f, i);
  bool band = false;
  for_each_candidate(
      pos, t, p, view, table, stencil.half_rows(i), [&](const float4& q, Slot s, Vec3 r, float r2) {
        const std::uint32_t k = original_index(q);
        const bool in = in_range_or_band<Defer>(images, cutoff_squared, i, k, r, r2, band) &&
                        stencil.allows(k, s, t);
        visit_stencil(f, acc, in, i, k, s, r, r2, images, ti, stencil);
      });
  if (Defer && band) return false;
  f.finish(i, acc);
  return true;
}

// One thread per target. ManyRegisters: the registers it wants (fewer warps, each with more
// loads in flight), for dense boxes.
// The slot of the t-th target: targets lists them when only some points are targets.
__device__ __forceinline__ Slot target_slot(const Slot* targets, Slot t) {
  return targets ? targets[t] : t;
}

template <bool ManyRegisters, bool Defer, class F, class Table, class Images, class Stencil>
__global__ void __launch_bounds__(grid_block_size, ManyRegisters ? 1 : 0)
    grid_thread_kernel(const float4* __restrict__ pos, const Slot* targets, Slot n,
                       GridGeometry view, Table table, float cutoff_squared, F f, Images images,
                       BandTargets band, Stencil stencil) {
  const Slot tid = blockIdx.x * grid_block_size + threadIdx.x;
  if (tid >= n) return;
  const Slot t = target_slot(targets, tid);
  if (!grid_thread_target<Defer>(pos, t, view, table, cutoff_squared, f, images, stencil))
    band.add(t);
}

constexpr int grid_max_rows = 49;  // (2 reach + 1)^2 rows for reach <= 3

// G lanes share target t's candidates, flattened into one list: the lanes find the rows' ranges
// together (a block of rows each), a prefix sum over the group places them one after the other
// in rows[] as (first slot - first flat index, end flat index); returns the list's length.
template <int G, class Table>
__device__ __forceinline__ Slot flatten_rows(const GridGeometry& view, const Table& table,
                                             const TargetCell& c, bool active, bool half, Slot t,
                                             int lane, uint2* rows) {
  constexpr int rows_per_lane_max = (grid_max_rows + G - 1) / G;
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
          row_range(view, table, c, r / side - reach, r % side - reach, half, t, s0, s1)))
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
      rows[r] = make_uint2(base[k] - flat, flat + length[k]);
      flat += length[k];
    }
  }
  __syncwarp();
  return group_total;
}

// G lanes per target over its flattened candidates: lane g takes candidates g, g + G, ... of the
// whole list, so every lane does the same work whatever the lengths of the rows, and
// neighbouring lanes read neighbouring sources. The lanes' states are combined in a fixed order
// (combine_lanes): results do not change between runs. For functors with a combine(): small
// inputs, where a thread per target would not fill the GPU.
// Target t of a group of G lanes (rows: the group's shared row table; an inactive group's
// lanes take part in the shuffles and finish nothing). False (nothing finished) when Defer found
// a candidate in the band.
template <int G, bool Defer, class F, class Table, class Images, class Stencil>
__device__ __forceinline__ bool grid_group_target(const float4* __restrict__ pos, Slot t,
                                                  bool active, const GridGeometry& view,
                                                  const Table& table, float cutoff_squared,
                                                  const F& f, const Images& images,
                                                  const Stencil& stencil, uint2* rows, int lane) {
  const float4 p = active ? pos[t] : make_float4(0, 0, 0, 0);
  const std::uint32_t i = original_index(p);
  const Slot group_total = flatten_rows<G>(view, table, locate(view, p), active,
                                           active && stencil.half_rows(i), t, lane, rows);

  // Unrolled by U: the slots of U candidates first (the row walk only moves forward), then U
  // independent loads in flight, then the U tests.
  constexpr int U = 4;
  const typename Images::Target ti = images.target(t);
  typename F::Accumulator acc{};
  bool band = false;
  int r = 0;
  uint2 row = rows[0];
  for (Slot first = lane; first < group_total; first += U * G) {
    Slot s[U];
#pragma unroll
    for (int u = 0; u < U; ++u) {
      const Slot fl = first + u * G;
      if (fl < group_total) {
        while (fl >= row.y) row = rows[++r];
        s[u] = row.x + fl;
      } else {
        s[u] = t;  // a valid slot; skipped below
      }
    }
    float4 q[U];
#pragma unroll
    for (int u = 0; u < U; ++u) q[u] = pos[s[u]];
#pragma unroll
    for (int u = 0; u < U; ++u) {
      Vec3 d{q[u].x - p.x, q[u].y - p.y, q[u].z - p.z};
      float r2 = squared_distance(d.x, d.y, d.z);
      const std::uint32_t k = original_index(q[u]);
      const bool in = in_range_or_band<Defer>(images, cutoff_squared, i, k, d, r2, band) &&
                      s[u] != t && stencil.allows(k, s[u], t);
      visit_stencil(f, acc, in, i, k, s[u], d, r2, images, ti, stencil);
    }
  }
  combine_lanes<G, F>(acc);
  if constexpr (Defer) {  // the group's lanes: G consecutive bits of the warp's ballot
    const unsigned lanes = __ballot_sync(0xffffffffu, band);
    const unsigned group_lanes =
        G == 32 ? 0xffffffffu : ((1u << G) - 1u) << ((threadIdx.x % 32) / G * G);
    if (lanes & group_lanes) return false;
  }
  if (active && lane == 0) {
    typename F::Accumulator total_state = initial_state(f, i);
    F::combine(total_state, acc);
    f.finish(i, total_state);
  }
  return true;
}

template <int G, bool Defer, class F, class Table, class Images, class Stencil>
__global__ void __launch_bounds__(grid_block_size)
    grid_group_kernel(const float4* __restrict__ pos, const Slot* targets, Slot n,
                      GridGeometry view, Table table, float cutoff_squared, F f, Images images,
                      BandTargets band, Stencil stencil) {
  constexpr int groups = grid_block_size / G;
  __shared__ uint2 rows[groups][grid_max_rows];
  const int group = threadIdx.x / G, lane = threadIdx.x % G;
  const Slot tid =
      static_cast<Slot>((blockIdx.x * std::uint64_t{grid_block_size} + threadIdx.x) / G);
  const bool active = tid < n;  // no early return: every lane takes part in the shuffles
  const Slot t = active ? target_slot(targets, tid) : 0;
  if (!grid_group_target<G, Defer>(pos, t, active, view, table, cutoff_squared, f, images, stencil,
                                   rows[group], lane) &&
      active && lane == 0)
    band.add(t);
}

// A warp per target for functors that emit entries (lists): the 32 lanes take 32 consecutive
// candidates at a time, and a ballot gives each taken pair its place among them, so the warp
// writes the target's entries together: coalesced stores instead of one scattered store per
// entry per thread (docs/benchmarks.md, "Neighbour lists"). Entries within a row keep the
// order of the candidates, the same on every run.
// Target t of a warp (rows: the warp's shared row table; active is uniform over the warp).
// False (nothing finished) when Defer found a candidate in the band.
template <bool Defer, class F, class Table, class Images, class Stencil>
__device__ __forceinline__ bool grid_emit_target(const float4* __restrict__ pos, Slot t,
                                                 bool active, const GridGeometry& view,
                                                 const Table& table, float cutoff_squared,
                                                 const F& f, const Images& images,
                                                 const Stencil& stencil, uint2* rows, int lane) {
  constexpr int G = 32;
  const float4 p = active ? pos[t] : make_float4(0, 0, 0, 0);
  const std::uint32_t i = original_index(p);
  const Slot total = flatten_rows<G>(view, table, locate(view, p), active,
                                     active && stencil.half_rows(i), t, lane, rows);
  const typename Images::Target ti = images.target(t);
  typename F::Accumulator next{};
  if (active) next = initial_state(f, i);
  const unsigned lanes_below = (1u << lane) - 1u;
  bool band = false;
  int r = 0;
  uint2 row = rows[0];
  for (Slot first = 0; first < total; first += G) {  // the same trip count on every lane
    const Slot fl = first + lane;
    bool take = false;
    std::uint32_t j = 0;
    Shift shift{};
    Vec3 d{0, 0, 0};
    float r2 = 0;
    if (fl < total) {
      while (fl >= row.y) row = rows[++r];
      const Slot s = row.x + fl;
      const float4 q = pos[s];
      d = Vec3{q.x - p.x, q.y - p.y, q.z - p.z};
      r2 = squared_distance(d.x, d.y, d.z);
      const std::uint32_t k = original_index(q);
      const bool in = in_range_or_band<Defer>(images, cutoff_squared, i, k, d, r2, band) &&
                      s != t && stencil.allows(k, s, t);
      // A pair the functor drops (per-pair cutoffs) takes no place: it would leave a hole.
      take = resolve(for_candidate(f, stencil.home(k)), images, ti, in, i, k, s, j, shift) &&
             f.within(i, j, shift, r2);
    }
    const unsigned taken = __ballot_sync(0xffffffffu, take);
    if (take) {
      typename F::Accumulator at = next + __popc(taken & lanes_below);
      apply(f, at, i, j, d, r2, shift);
    }
    next += __popc(taken);
  }
  // The whole warp's target: its entries so far are written again.
  if (Defer && __any_sync(0xffffffffu, band)) return false;
  if (active && lane == 0) f.finish(i, next);
  return true;
}

template <bool Defer, class F, class Table, class Images, class Stencil>
__global__ void __launch_bounds__(grid_block_size)
    grid_emit_kernel(const float4* __restrict__ pos, const Slot* targets, Slot n, GridGeometry view,
                     Table table, float cutoff_squared, F f, Images images, BandTargets band,
                     Stencil stencil) {
  constexpr int groups = grid_block_size / 32;
  __shared__ uint2 rows[groups][grid_max_rows];
  const int group = threadIdx.x / 32, lane = threadIdx.x % 32;
  const Slot tid =
      static_cast<Slot>((blockIdx.x * std::uint64_t{grid_block_size} + threadIdx.x) / 32);
  const bool active = tid < n;  // the whole warp shares t: uniform
  const Slot t = active ? target_slot(targets, tid) : 0;
  if (!grid_emit_target<Defer>(pos, t, active, view, table, cutoff_squared, f, images, stencil,
                               rows[group], lane) &&
      active && lane == 0)
    band.add(t);
}

// The targets a deferring launch left (BandTargets), each computed whole with the exact
// predicate. A warp per target, through the functor's warp-wide body where it has one: a
// target walked by one thread took as long as the whole first launch (110-290 us on an H100,
// docs/grid.md); a grid-stride loop, since only the device knows how many.
template <class F, class Table, class Images, class Stencil>
__global__ void __launch_bounds__(grid_block_size)
    grid_band_kernel(const float4* __restrict__ pos, GridGeometry view, Table table,
                     float cutoff_squared, F f, Images images, BandTargets band, Stencil stencil) {
  constexpr int groups = grid_block_size / 32;
  __shared__ uint2 rows[groups][grid_max_rows];
  const int group = threadIdx.x / 32, lane = threadIdx.x % 32;
  const Slot count = band.list[0];
  const bool flat = view.grid.reach <= 3;  // the row table holds (2 * 3 + 1)^2 rows
  for (Slot k = (blockIdx.x * grid_block_size + threadIdx.x) / 32; k < count;
       k += gridDim.x * groups) {  // k is uniform over the warp
    const Slot t = band.list[1 + k];
    if constexpr (emits_entries<F>::value) {
      if (flat) {
        grid_emit_target<false>(pos, t, true, view, table, cutoff_squared, f, images, stencil,
                                rows[group], lane);
        continue;
      }
    }
    if constexpr (has_combine<F>::value) {
      if (flat) {
        grid_group_target<32, false>(pos, t, true, view, table, cutoff_squared, f, images, stencil,
                                     rows[group], lane);
        continue;
      }
    }
    if (lane == 0)
      grid_thread_target<false>(pos, t, view, table, cutoff_squared, f, images, stencil);
    __syncwarp();
  }
}

// Runs functor f for every target of the grid pass `pass`, on `stream`.
template <class F>
void run_grid(const PairPass& pass, const F& f, cudaStream_t stream) {
  const GridPass& g = pass.grid;
  const auto* pos = static_cast<const float4*>(g.particles);
  const Slot* targets = g.targets;
  const Slot n = static_cast<Slot>(pass.n);
  const float c2 = pass.cutoff_squared;
  const BandTargets band{g.band_targets};
  const auto launch = [&](const auto& table, const auto& images, const auto& stencil, auto defer) {
    constexpr bool Defer = decltype(defer)::value;
    if constexpr (emits_entries<F>::value) {
      if (g.geometry.grid.reach <= 3) {  // the flattened row table holds (2 * 3 + 1)^2 rows
        grid_emit_kernel<Defer>
            <<<blocks_for(std::uint64_t{n} * 32, grid_block_size), grid_block_size, 0, stream>>>(
                pos, targets, n, g.geometry, table, c2, f, images, band, stencil);
        return;
      }
    }
    GridKernel kernel = g.kernel;
    if constexpr (!has_combine<F>::value)
      kernel = kernel == GridKernel::thread_many_registers ? kernel : GridKernel::thread;
    const auto group = [&](auto lanes) {
      if constexpr (has_combine<F>::value) {
        constexpr int G = decltype(lanes)::value;
        grid_group_kernel<G, Defer>
            <<<blocks_for(std::uint64_t{n} * G, grid_block_size), grid_block_size, 0, stream>>>(
                pos, targets, n, g.geometry, table, c2, f, images, band, stencil);
      }
    };
    switch (kernel) {
      case GridKernel::thread:
        grid_thread_kernel<false, Defer>
            <<<blocks_for(n, grid_block_size), grid_block_size, 0, stream>>>(
                pos, targets, n, g.geometry, table, c2, f, images, band, stencil);
        break;
      case GridKernel::thread_many_registers:
        grid_thread_kernel<true, Defer>
            <<<blocks_for(n, grid_block_size), grid_block_size, 0, stream>>>(
                pos, targets, n, g.geometry, table, c2, f, images, band, stencil);
        break;
      case GridKernel::lanes4:
        group(std::integral_constant<int, 4>{});
        break;
      case GridKernel::lanes8:
        group(std::integral_constant<int, 8>{});
        break;
      case GridKernel::lanes16:
        group(std::integral_constant<int, 16>{});
        break;
      case GridKernel::lanes32:
        group(std::integral_constant<int, 32>{});
        break;
    }
  };
  // The band's targets: a second launch that loops over them, a warp for every 16 targets of the
  // pass (the band holds a few per thousand; an empty launch of a warp per target was 1,250
  // blocks at 10^4 targets), at most 2,048 blocks.
  const auto launch_deferred = [&](const auto& table, const auto& images, const auto& stencil) {
    RAYCUT_CUDA_CHECK(cudaMemsetAsync(band.list, 0, sizeof(Slot), stream));
    launch(table, images, stencil, std::true_type{});
    RAYCUT_CUDA_CHECK_LAUNCH();
    const unsigned blocks = std::min(blocks_for(std::uint64_t{n} * 2, grid_block_size), 2048u);
    if (blocks > 0)
      grid_band_kernel<<<blocks, grid_block_size, 0, stream>>>(pos, g.geometry, table, c2, f,
                                                               images, band, stencil);
  };
  const auto run = [&](const auto& table, const auto& images, const auto& stencil) {
    using Images = std::decay_t<decltype(images)>;
    if constexpr (Images::banded && defers_band<F>) {
      // Not where every pair is decided in double (exact vectors: float_in = 0), which would
      // leave every target to the second launch.
      if (band.list && images.exact.float_in > 0 && !band_inline_requested()) {
        launch_deferred(table, images, stencil);
        return;
      }
    }
    launch(table, images, stencil, std::false_type{});
  };
  // The half stencil where it is asked and the image counts are known where there are images
  // (else the index's rows, one choice of the rows any_row allows). Half lists take no queries.
  const auto with_stencil = [&](const auto& table, const auto& images) {
    if constexpr (has_any_row<F>::value) {
      if (wants_stencil(f) && pass.images.candidates_are_sources &&
          (!pass.images.active() || pass.images.image_counts != nullptr)) {
        run(table, images,
            StencilRows{n, pass.images.active() ? pass.images.image_counts : nullptr});
        return;
      }
    }
    run(table, images, FullStencil{});
  };
  with_images<F>(
      pass,
      [&](const auto& images) {
        if (g.dense)
          with_stencil(DenseTable{g.dense_table.start}, images);
        else
          with_stencil(CompactTable{g.compact_table}, images);
      },
      stream);
  RAYCUT_CUDA_CHECK_LAUNCH();
}

}  // namespace raycut::detail::cuda
