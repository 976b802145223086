// What a built method exposes so that a functor compiled by the caller runs through the
// method's own traversal (include/raycut/pairs.hpp, include/raycut/cuda/pairs.cuh): plain data,
// passed to kernels by value (but DeferredImages, asked on the host before a launch). Not a
// stable interface: it follows the methods' internals.
#pragma once

#include <cstddef>
#include <cstdint>

#include "raycut/detail/cell_grid.hpp"

namespace raycut {
class Engine;
}  // namespace raycut

namespace raycut::detail {

enum class PassKind {
  none,             // nothing built (N = 0), or a method without a pass users can run (OptiX)
  host,             // CPU methods: runs of candidates per target
  brute_force_gpu,  // every target against every source
  grid_paper,       // the paper's dense grid, 27 cells
  grid,             // the production grid: dense or compact table, culled rows
};

struct PointImage;

// Points with images are float positions rounded at the scale of their box, so the float
// predicate on them can misjudge a pair within ~(box / C) 2^-23 of the cutoff, and judge
// (i, j, S) and (j, i, -S) apart. Every pass (CPU and GPU) therefore decides each candidate whose
// float r2 lies in the band [float_in, float_out) in double, from the caller's own positions:
// r = (x_j - x_i) + S . cell, which is exactly antisymmetric (IEEE rounding is symmetric), so a
// full list holds (i, j, S) iff it holds (j, i, -S), and every pair is the float64 answer.
// Plain data: the arrays are in the method's memory space, the struct is passed by value to
// kernels (detail/images.hpp).
struct ExactImages {
  const float* sources = nullptr;         // the caller's particles (N, 3), as given
  const double* sources64 = nullptr;      // the same in double when given so (else null)
  const float* queries = nullptr;         // the caller's query points (M, 3); null: none
  const PointImage* image = nullptr;      // by point: source and shift T
  const std::uint32_t* system = nullptr;  // by point; null: one system
  const double* cells = nullptr;          // per system, 9 each: rows a, b, c
  double cutoff_squared = 0;              // C^2 in double
  // A float r2 below float_in is in for certain, at or above float_out out for certain. Cells
  // at least sqrt(float_out) wide offer every pair in range. float_in is 0 with exact_vectors.
  float float_in = 0, float_out = 0;
  // How far a float point may lie from its real position, per coordinate (float_band_slack).
  double rounding = 0;
  // Boxes so large that float r is off by more than 2^-16 C: every pair's r from the double
  // vector (rounded once), not only the band's.
  bool exact_vectors = false;
};

// CPU methods hand candidates over in runs whose positions lie side by side (a row of cells, a
// system), so that the in-range test runs over arrays, vectorised and without a branch per
// candidate (pairs.hpp): point point(t) at (x[t], y[t], z[t]), t < count. x, y and z are readable
// (any finite values) up to count rounded up to `padding`: the test runs whole vectors.
struct CandidateRun {
  static constexpr std::size_t padding = 8;
  // No default values: a pass keeps an array of them per target, left unset until written.
  const float* x;
  const float* y;
  const float* z;
  const std::uint32_t* index;  // the points; null: first + t
  // The caller's particle each point is (its source, for an image), readable as x is; null: not
  // given. With it a half list drops the candidates below its row before any scalar work.
  const std::uint32_t* source;
  // The points' image-table entries in run order (null: the pass reads the table by point): a
  // list's j and S then come from memory read in sequence, not from the caller's order at random.
  const PointImage* image;
  std::uint32_t first;
  // The slot of its first point in the method's order of points (HostPass::slots; 0 where the
  // method gives none): a half stencil takes the slots after the target's.
  std::uint32_t slot;
  std::size_t count;
  std::uint32_t point(std::size_t t) const {
    return index ? index[t] : first + static_cast<std::uint32_t>(t);
  }
};
// The most runs a CPU method gives one target (the cell list: its 27 cells).
constexpr std::size_t max_candidate_runs = 27;
struct HostPass {
  const void* method = nullptr;
  // Writes runs (at most max_candidate_runs) that hold every candidate point of target i (i
  // itself allowed), each point at most once, and returns how many.
  std::size_t (*runs)(const void* method, std::size_t i, CandidateRun* out) = nullptr;
  const float* xyz = nullptr;  // (points, 3): the caller's order, or the points with images
  // The n targets in the order to visit them (the cell list: cell order, so that consecutive
  // targets share cached cells); null: 0 .. n - 1.
  const std::uint32_t* order = nullptr;
  // With `order`: the targets' positions in that order, 3 each, read in sequence where xyz
  // would be read at random (null: read xyz).
  const float* order_xyz = nullptr;
  // By target: its slot in the order of the runs' points (CandidateRun::slot), for the half
  // stencil (ListOptions::any_row); null: the method has none (lists keep the index's rows).
  const std::uint32_t* slots = nullptr;
};

struct BruteForcePass {
  const float* xyz = nullptr;             // (points, 3) on the device
  const std::uint32_t* system = nullptr;  // per point (batches); null: one system
};

// Particles in cell order, one array per coordinate as in the paper.
struct GridPaperPass {
  const float* x = nullptr;
  const float* y = nullptr;
  const float* z = nullptr;
  const std::uint32_t* index = nullptr;  // slot -> caller's index
  const std::uint32_t* start = nullptr;  // cells + 1 entries
  CellGrid grid;
};

// The production grid (src/cuda/grid_build.cu builds it; detail/cuda/grid_pass.cuh walks it).
// Cells are anisotropic: `grid` gives the y and z cells (C/k wide), `xgrid` the x cells,
// x_split times narrower; a row of x cells is one range of slots whatever their width.
struct GridGeometry {
  CellGrid grid, xgrid;
  float x_cells_per_cell;  // xgrid cells per grid cell, along x
  float reach_cells;       // the cutoff in cell units, inflated so that culling stays conservative
  bool cull;
  // Batches: system s's cells are z layers [s * layer_stride, s * layer_stride + layer_cells) of
  // the grid (layer_stride - layer_cells >= reach empty layers between systems, so no stencil
  // reaches another system); system[k] of point k. layer_cells = 0: one system.
  const std::uint32_t* system = nullptr;
  std::uint32_t layer_cells = 0, layer_stride = 0;
};

// The particles of cells [xa, xb] of row `row` are slots [start[row * dims0 + xa],
// start[row * dims0 + xb + 1]).
struct DenseTablePass {
  const std::uint32_t* start = nullptr;  // cell_count + 1 entries
};

// Non-empty cells only: sorted keys with their first slots, and a hash table from row to the
// row's run of unique cells.
struct CompactTablePass {
  const std::uint64_t* cell_keys = nullptr;   // non-empty cells, ascending
  const std::uint32_t* cell_start = nullptr;  // runs + 1 entries
  const std::uint64_t* row_keys = nullptr;    // hash table: row id, or ~0
  const std::uint32_t* row_cells = nullptr;   // hash table: the row's unique cells [x, y), pairs
  std::uint64_t mask = 0;
  int shift = 0;
};

// How the grid's kernels are launched, chosen at build (src/cuda/grid_policy.hpp).
enum class GridKernel {
  thread,                 // a thread per target, within the compiler's register budget
  thread_many_registers,  // a thread per target with the registers it wants (dense boxes)
  lanes4,                 // 4, 8, 16 or 32 lanes share each target (small inputs)
  lanes8,
  lanes16,
  lanes32,
};

struct GridPass {
  const void* particles = nullptr;         // float4 per slot, in cell order: x y z, w = point index
  const std::uint32_t* targets = nullptr;  // the slots of the targets in slot order; null: all
  GridGeometry geometry;
  bool dense = true;
  DenseTablePass dense_table;
  CompactTablePass compact_table;
  GridKernel kernel = GridKernel::thread;
  // With images: room for the slots of every target whose candidates reach the float band
  // (band_targets[0] their count, then the slots), decided by a second launch; null without.
  std::uint32_t* band_targets = nullptr;
};

// Points with images (src/core/images.hpp): per point k the caller's source index (or
// not_a_source: a query point) and its shift T_k, the point being x_source + T_k . cell; a pair
// (target i, point k) has S = T_k - T_i. One 16-byte load per pair.
constexpr std::uint32_t not_a_source = 0xFFFFFFFFu;
struct alignas(16) PointImage {
  std::uint32_t source;
  std::int32_t shift[3];
};
// A table of the points' images in a traversal's own order, made on the first pass that reads
// it (the grid's, in slot order: most kernels never read one, docs/periodic.md).
class DeferredImages {
 public:
  // The table; the first call queues its making on `stream` (a cudaStream_t), and every call
  // orders it before the work queued next on `stream`.
  virtual const PointImage* on(void* stream) const = 0;

 protected:
  ~DeferredImages() = default;
};

// Null: the points are the caller's particles.
struct ImageTables {
  const PointImage* image = nullptr;         // by point
  const DeferredImages* deferred = nullptr;  // set: the traversal reads deferred->on(stream)
  // Every point the traversal offers as a candidate is some particle's image: no query points,
  // or a structure that never offers them (the CPU cell list). Then a functor that reads
  // neither j nor S runs the open traversal (with_images).
  bool candidates_are_sources = true;
  // What decides the pairs of the float band in double (see ExactImages): a host struct, its
  // arrays where the traversal runs. Set whenever `image` is.
  const ExactImages* exact = nullptr;
  // By source: how many image points it has (both expansions keep them; null: not known). A
  // particle without images has no image within the cutoff, which lets a half stencil leave it
  // the slots before its own (grid_pass.cuh, StencilRows; pairs.hpp, run_host).
  const std::uint32_t* image_counts = nullptr;
  bool active() const { return image != nullptr; }
  // What a traversal launched on `stream` indexes: by point, or the deferred table.
  const PointImage* table(void* stream) const { return deferred ? deferred->on(stream) : image; }
};

struct PairPass {
  PassKind kind = PassKind::none;
  const char* method = "";
  std::size_t n = 0;       // targets: points [0, n)
  std::size_t points = 0;  // every point a candidate source (n without images)
  ImageTables images;
  float cutoff_squared = 0;
  HostPass host;
  BruteForcePass brute_force;
  GridPaperPass grid_paper;
  GridPass grid;
};

// The traversal view of a built engine: what for_each_pair (pairs.hpp, cuda/pairs.cuh) runs a
// caller's functor through. Kind none: an engine over no points. Throws Error(invalid_argument)
// for an engine not built, and Error(unsupported) for a method without a pass for a caller's
// functor (the OptiX methods).
struct PairPassAccess {
  static PairPass of(const Engine& engine);
};

}  // namespace raycut::detail
