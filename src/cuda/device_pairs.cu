// The stream-ordered small-system pair list (raycut/device_pairs.hpp): brute force within each
// system, a block per particle up to 2,048 particles and 8 to 32 lanes per particle above
// (row_team_threads), every distance in double. Three launches and a memset per call without cells,
// all on the context's stream: the lattices (one per cell), the rows (count, offset and fill in
// one, list_rows), pad. No host synchronisation and no allocation outside the context's memory
// resource, so a CUDA graph captures it. Compiled with --fmad=false (CMakeLists.txt): the device
// rounds every double as the host mirror below does.
#include <cuda_runtime.h>
#include <cub/device/device_radix_sort.cuh>
#include <cub/device/device_scan.cuh>
#include <cuda/atomic>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include "core/validation.hpp"
#include "cuda/device_buffer.cuh"
#include "cuda/device_pairs_host.hpp"
#include "raycut/detail/cuda/check.cuh"
#include "raycut/device_pairs.hpp"
#include "raycut/error.hpp"

namespace raycut {
namespace {

constexpr int warp_size = 32;
constexpr int block_threads = 128;  // four rows per block, or one (Team)
constexpr int block_warps = block_threads / warp_size;
// Up to this many rows, a block per row. Chosen at ~120 registers a thread, when an H100
// multiprocessor held 16 warps, 2,112 in all: below that many rows a warp per row leaves warps
// idle and walks all n sources in each, where a block per row walks n / 128 per thread in
// ceil(4 n / 2,112) waves, never longer (half as long at 1,000 rows). Not measured again since
// the row kernels went to 64-72 registers (28-32 warps a multiprocessor).
constexpr std::size_t rows_for_block_teams = 2048;
// The blocks of the one-launch pass (list_rows) that a multiprocessor must hold at once: 8 caps
// it at 64 registers a thread (from 72, with ~90 bytes of spills), so that a thousand rows of a
// block each run in one wave on an H100 (132 x 8 blocks): 0.86x the time at 1,000 particles.
// The cells path's count (95 registers) bounded to 80 was 3 % slower on single systems: unbounded.
constexpr int list_rows_blocks_per_multiprocessor = 8;
// Above rows_for_block_teams rows, each row gets the fewest lanes (8, 16 or 32) that still make
// this many threads, an H100's or H200's 132 multiprocessors x 2,048: the GPU stays full, a row
// of a small system fills its lanes (100 sources: 7 rounds of 16 lanes, against 4 of 32 with
// the last an eighth full), and fewer lanes share its frame and its tile's look-back. Measured
// on an H100 (docs/benchmarks.md), all pairs from a graph: 256 x 100 188 -> 159 us (16 lanes;
// 8: 171), 512 x 128 322 -> 239 (8 lanes; 16: 243), 32 x 100 unchanged at 32 lanes (16: 43
// against 41); cells at 512 x 128 564 -> 411 (8 lanes). At 4,000 particles with cells 16 lanes
// were faster than the 32 chosen (102 against 112 us): the rule leaves that.
constexpr std::size_t threads_to_fill = std::size_t(132) * 2048;
int row_team_threads(std::size_t rows) {
  if (rows <= rows_for_block_teams) return block_threads;
  for (int lanes : {8, 16})
    if (rows * lanes >= threads_to_fill) return lanes;
  return warp_size;
}
constexpr unsigned all_lanes = 0xffffffffu;
// How far below 1/2 an axis's reach must stay for the single image (Lattice::single_image), and
// the largest |f_a| that for_each_image takes without checks: f_a's rounding, ~1e-16 |f_a| per
// term, stays far below the slack, and f_a + reach (below 2^23, max_images_per_pair) fits an int.
constexpr double single_image_slack = 1e-6;
constexpr double largest_plain_f = 1e8;

struct Input {
  const void* xyz = nullptr;
  std::int64_t n = 0;
  const void* cells = nullptr;
  std::int64_t cell_count = 0;
  const bool* pbc = nullptr;
  std::int64_t pbc_count = 0;
  const std::int64_t* batch = nullptr;
  double cutoff = 0, cutoff2 = 0;
  bool half = false;
  const int* run_if = nullptr;  // PairOptions::run_if
  std::int64_t systems = 0;     // StaticPairs::systems: a list per system (0: one list)
  bool by_cells = false;        // the sources by cells (PairOptions::search)
};

// A cell and its pbc row, as the pairs of its systems need them: the lattice rows, and the
// reciprocal vectors that bound each pair's images. Computed once per cell (lattices_kernel), not
// per row: the Gram-Schmidt, the inverse and their square roots and divisions in double were
// more instructions than a row's pair tests at a thousand particles.
struct Lattice {
  int code = 0;  // a count code (raycut/device_pairs.hpp) when the cell is bad; its rows report it
  bool periodic[3] = {false, false, false};
  bool any_periodic = false;
  double row[3][3] = {};  // lattice rows (periodic ones only used)
  // g[a]: column a of the inverse of the basis (periodic rows, open ones completed by an
  // orthonormal complement): f_a = d . g[a] is d's coordinate along row a, and for every image
  // r = d + S . cell, r . g[a] = f_a + S_a, so |f_a + S_a| <= |r| |g[a]| < cutoff |g[a]|.
  double g[3][3] = {{1, 0, 0}, {0, 1, 0}, {0, 0, 1}};
  // cutoff |g[a]|: no pair within the cutoff is farther apart than this along axis a (open axes
  // too: the cells use it)
  double reach[3] = {};
  // Every periodic axis thicker than twice the cutoff (reach < 1/2, with room for rounding): a
  // pair then has at most one image within the cutoff, S_a = round(-f_a) (for_each_image).
  bool single_image = false;
};

// What a row needs to enumerate its pairs: its system's particles, its own position, and its
// system's lattice.
struct Frame : Lattice {
  std::int64_t lo = 0, hi = 0;  // the row's system: particles [lo, hi)
  double xi[3] = {};            // the row's position
};

template <class Real>
__host__ __device__ double load(const void* p, std::int64_t k) {
  return static_cast<double>(static_cast<const Real*>(p)[k]);
}

__host__ __device__ double dot(const double* a, const double* b) {
  return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

// First index in [begin, end) whose batch value is > value (upper) or >= value (lower); end if
// none.
__host__ __device__ std::int64_t bound(const std::int64_t* batch, std::int64_t begin,
                                       std::int64_t end, std::int64_t value, bool upper) {
  std::int64_t lo = begin, hi = end;
  while (lo < hi) {
    const std::int64_t mid = lo + (hi - lo) / 2;
    if (upper ? batch[mid] <= value : batch[mid] < value)
      lo = mid + 1;
    else
      hi = mid;
  }
  return lo;
}
__host__ __device__ std::int64_t bound(const std::int64_t* batch, std::int64_t n,
                                       std::int64_t value, bool upper) {
  return bound(batch, 0, n, value, upper);
}

// Row i's system, [lo, hi), galloping out from i: systems are small beside the batch, so the
// loads stay near i (in cache) and number ~2 log2 of the system's size, not of the batch's (a
// binary search over 65,536 rows was 32 dependent loads, most of a row's time in a batch).
__host__ __device__ void system_of(const std::int64_t* batch, std::int64_t n, std::int64_t i,
                                   std::int64_t& lo, std::int64_t& hi) {
  const std::int64_t value = batch[i];
  std::int64_t known = i, step = 1, probe = i - 1;  // batch[known] >= value
  while (probe >= 0 && batch[probe] >= value) {
    known = probe;
    step *= 2;
    probe = i - step;
  }
  lo = bound(batch, probe < 0 ? 0 : probe + 1, known, value, false);
  known = i, step = 1, probe = i + 1;  // batch[known] <= value
  while (probe < n && batch[probe] <= value) {
    known = probe;
    step *= 2;
    probe = i + step;
  }
  hi = bound(batch, known + 1, probe < n ? probe : n, value, true);
}

// The lattices a call computes: one per cell, or per pbc row where those are more (0: open).
__host__ __device__ std::int64_t lattice_count(const Input& in) {
  if (!in.cells) return 0;
  return in.cell_count > in.pbc_count ? in.cell_count : in.pbc_count;
}

// The lattice of systems with index s (cell s or 0, pbc row s or 0); its code says if it is bad.
template <class Real>
__host__ __device__ void make_lattice(const Input& in, std::int64_t s, Lattice& f) {
  const std::int64_t c = in.cell_count > 1 ? s : 0;
  const std::int64_t p = in.pbc_count > 1 ? s : 0;
  if (c >= in.cell_count || (in.pbc && p >= in.pbc_count)) {
    f.code = int(count_batch_out_of_range);
    return;
  }
#pragma unroll
  for (int a = 0; a < 3; ++a) f.reach[a] = in.cutoff;  // the axes themselves, while all open
    // Every loop over axes is unrolled and indexes its arrays with constants only: the lattice then
    // lives in registers, where a runtime index (a Gram-Schmidt slot counter) put it and the
    // arrays below in a 336-byte stack frame.
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    f.periodic[a] = in.pbc ? in.pbc[3 * p + a] : true;
    f.any_periodic = f.any_periodic || f.periodic[a];
#pragma unroll
    for (int k = 0; k < 3; ++k) f.row[a][k] = load<Real>(in.cells, 9 * c + 3 * a + k);
  }
  if (!f.any_periodic) return;
  // The basis: periodic rows as given, open ones replaced by unit vectors orthogonal to the rest
  // (Gram-Schmidt: the periodic rows in axis order, then the open ones), so that only the
  // periodic rows decide the images. q[a] is axis a's orthonormal vector; it is projected out of
  // the later axes in that same order.
  double basis[3][3], q[3][3];
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    if (!f.periodic[a]) continue;
    double w[3] = {f.row[a][0], f.row[a][1], f.row[a][2]};
    const double length = sqrt(dot(w, w));
    if (!isfinite(length) || length == 0) {
      f.code = int(count_invalid_cell);
      return;
    }
#pragma unroll
    for (int m = 0; m < a; ++m) {
      if (!f.periodic[m]) continue;
      const double along = dot(f.row[a], q[m]);
#pragma unroll
      for (int k = 0; k < 3; ++k) w[k] -= along * q[m][k];
    }
    const double rest = sqrt(dot(w, w));
    if (!(rest > 1e-9 * length)) {
      f.code = int(count_invalid_cell);
      return;
    }
    const double inverse_rest = 1 / rest;  // one division, not three: a long chain in double
#pragma unroll
    for (int k = 0; k < 3; ++k) {
      q[a][k] = w[k] * inverse_rest;
      basis[a][k] = f.row[a][k];
    }
  }
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    if (f.periodic[a]) continue;
    double best[3] = {0, 0, 0}, best_length = -1;
#pragma unroll
    for (int e = 0; e < 3; ++e) {
      double w[3] = {e == 0 ? 1.0 : 0.0, e == 1 ? 1.0 : 0.0, e == 2 ? 1.0 : 0.0};
      // Earlier slots: every periodic axis, then the open axes before a.
#pragma unroll
      for (int m = 0; m < 3; ++m) {
        if (!f.periodic[m]) continue;
        const double along = dot(w, q[m]);
#pragma unroll
        for (int k = 0; k < 3; ++k) w[k] -= along * q[m][k];
      }
#pragma unroll
      for (int m = 0; m < a; ++m) {
        if (f.periodic[m]) continue;
        const double along = dot(w, q[m]);
#pragma unroll
        for (int k = 0; k < 3; ++k) w[k] -= along * q[m][k];
      }
      const double length = sqrt(dot(w, w));
      if (length > best_length) {
        best_length = length;
#pragma unroll
        for (int k = 0; k < 3; ++k) best[k] = w[k];
      }
    }
    const double inverse_length = 1 / best_length;
#pragma unroll
    for (int k = 0; k < 3; ++k) q[a][k] = basis[a][k] = best[k] * inverse_length;
  }
  // The inverse by cofactors: basis . inverse = I, so column a of the inverse is g[a].
  const double(&m)[3][3] = basis;
  const double cof[3][3] = {
      {m[1][1] * m[2][2] - m[1][2] * m[2][1], m[1][2] * m[2][0] - m[1][0] * m[2][2],
       m[1][0] * m[2][1] - m[1][1] * m[2][0]},
      {m[0][2] * m[2][1] - m[0][1] * m[2][2], m[0][0] * m[2][2] - m[0][2] * m[2][0],
       m[0][1] * m[2][0] - m[0][0] * m[2][1]},
      {m[0][1] * m[1][2] - m[0][2] * m[1][1], m[0][2] * m[1][0] - m[0][0] * m[1][2],
       m[0][0] * m[1][1] - m[0][1] * m[1][0]}};
  const double det = m[0][0] * cof[0][0] + m[0][1] * cof[0][1] + m[0][2] * cof[0][2];
  if (!isfinite(det) || det == 0) {
    f.code = int(count_invalid_cell);
    return;
  }
  const double inverse_det = 1 / det;
#pragma unroll
  for (int a = 0; a < 3; ++a) {  // inverse[k][a] = cof[a][k] / det, so g[a][k] = cof[a][k] / det
#pragma unroll
    for (int k = 0; k < 3; ++k) f.g[a][k] = cof[a][k] * inverse_det;
    f.reach[a] = in.cutoff * sqrt(dot(f.g[a], f.g[a]));
  }
  // The images a pair can have, ~prod(2 reach + 1) over the periodic axes (+ 2 for rounding):
  // past the limit a cell far thinner than the cutoff would keep the GPU busy for hours.
  double images = 1;
  f.single_image = true;
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    if (!f.periodic[a]) continue;
    images *= 2 * f.reach[a] + 3;
    f.single_image = f.single_image && f.reach[a] < 0.5 - single_image_slack;
  }
  if (!(images <= max_images_per_pair)) f.code = int(count_too_many_images);
}

// The pass's first launch: it zeroes the pass's counters (`words`, in place of a memset: one
// operation fewer a call, on the host and in a graph) and makes the systems' lattices.
template <class Real>
__global__ void lattices_kernel(Input in, Lattice* lattices, std::int64_t count,
                                unsigned long long* words, std::size_t word_count) {
  const std::int64_t s = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  for (std::size_t w = static_cast<std::size_t>(s); w < word_count;
       w += std::size_t(gridDim.x) * blockDim.x)
    words[w] = 0;
  if (s >= count || (in.run_if && *in.run_if == 0)) return;
  Lattice f;
  make_lattice<Real>(in, s, f);
  lattices[s] = f;
}

// The row's frame, or a negative count code (raycut/device_pairs.hpp) for bad input of this row.
template <class Real>
__host__ __device__ int make_frame(const Input& in, std::int64_t i, const Lattice* lattices,
                                   Frame& f) {
#pragma unroll
  for (int k = 0; k < 3; ++k) {
    f.xi[k] = load<Real>(in.xyz, 3 * i + k);
    if (!isfinite(f.xi[k])) return int(count_non_finite_position);
  }
  std::int64_t system = 0;
  f.lo = 0;
  f.hi = in.n;
  if (in.batch) {
    system = in.batch[i];
    if (i + 1 < in.n && in.batch[i + 1] < system) return int(count_unsorted_batch);
    system_of(in.batch, in.n, i, f.lo, f.hi);
  }
  if (system < 0 || (in.systems > 0 && system >= in.systems))  // open systems too
    return int(count_batch_out_of_range);
  if (!in.cells) {
#pragma unroll
    for (int a = 0; a < 3; ++a) f.reach[a] = in.cutoff;
    return 0;
  }
  if ((in.cell_count > 1 && system >= in.cell_count) ||
      (in.pbc_count > 1 && system >= in.pbc_count))
    return int(count_batch_out_of_range);
  static_cast<Lattice&>(f) = lattices[in.cell_count > 1 || in.pbc_count > 1 ? system : 0];
  return f.code;
}

// The shifts [first, last] along one periodic axis from their bounds in double; false: none. A
// bound that is not finite (a non-finite position, which that particle's own row reports as a
// count code) gives none, and bounds past the int32 shifts are clamped: converting them to int
// unchecked is undefined, and on the GPU saturates (-inf to INT_MIN, NaN to 0), which made one
// infinite coordinate loop over 2^31 images per pair. The limit leaves ++s room below INT_MAX.
__host__ __device__ bool shift_range(double low, double high, int& first, int& last) {
  constexpr double limit = 2147483646.0;
  if (!(isfinite(low) && isfinite(high))) return false;
  low = fmax(low, -limit);
  high = fmin(high, limit);
  if (low > high) return false;
  first = static_cast<int>(low);
  last = static_cast<int>(high);
  return true;
}

// A source of a row: its index (-1: none, or one that a half list skips) and its position.
struct Source {
  std::int64_t j = -1;
  double x[3] = {};
};

// r = d + S . cell, the same operations in the same order for every path, so that (j, i, -S)
// gives -r exactly and the full list is symmetric.
__host__ __device__ inline void image_vector(const Frame& f, const double* d, int sx, int sy,
                                             int sz, double* r) {
#pragma unroll
  for (int k = 0; k < 3; ++k) {
    r[k] = d[k];
    if (f.periodic[0]) r[k] += sx * f.row[0][k];
    if (f.periodic[1]) r[k] += sy * f.row[1][k];
    if (f.periodic[2]) r[k] += sz * f.row[2][k];
  }
}

// The shifts along periodic axis a that can hold an image within the cutoff, as doubles: a
// margin far above the rounding of f_a and reach, so extra images are decided exactly later.
__host__ __device__ inline void shift_bounds(const Frame& f, const double* fa, int a, double& low,
                                             double& high) {
  const double margin = 1e-9 * (1 + fabs(fa[a]) + f.reach[a]);
  low = ceil(-fa[a] - f.reach[a] - margin);
  high = floor(-fa[a] + f.reach[a] + margin);
}

// Calls visit(S) for every S in [first, last] (lexicographic order) whose image (i, j, S) is
// within the cutoff; returns how many.
template <class Visit>
__host__ __device__ std::uint32_t visit_shifts(const Input& in, const Frame& f, std::int64_t i,
                                               std::int64_t j, const double* d, const int* first,
                                               const int* last, Visit&& visit) {
  std::uint32_t hits = 0;
  for (int sx = first[0]; sx <= last[0]; ++sx)
    for (int sy = first[1]; sy <= last[1]; ++sy)
      for (int sz = first[2]; sz <= last[2]; ++sz) {
        if (i == j) {
          if (sx == 0 && sy == 0 && sz == 0) continue;
          // Half lists keep the self-image with S lexicographically positive.
          if (in.half && !(sx > 0 || (sx == 0 && (sy > 0 || (sy == 0 && sz > 0))))) continue;
        }
        double r[3];
        image_vector(f, d, sx, sy, sz, r);
        if (dot(r, r) < in.cutoff2) {
          const int s[3] = {sx, sy, sz};
          visit(s);
          ++hits;
        }
      }
  return hits;
}

// Calls visit(S) for every in-range image (i, j, S) of row i, in lexicographic order of S;
// returns how many.
template <class Visit>
__host__ __device__ std::uint32_t for_each_image(const Input& in, const Frame& f, std::int64_t i,
                                                 const Source& source, Visit&& visit) {
  const std::int64_t j = source.j;
  double d[3];
#pragma unroll
  for (int k = 0; k < 3; ++k) d[k] = source.x[k] - f.xi[k];
  if (!f.any_periodic) {
    if (i == j || !(dot(d, d) < in.cutoff2)) return 0;
    const int zero[3] = {0, 0, 0};
    visit(zero);
    return 1;
  }
  double fa[3];
#pragma unroll
  for (int a = 0; a < 3; ++a) fa[a] = f.periodic[a] ? dot(d, f.g[a]) : 0.0;
  int first[3] = {0, 0, 0}, last[3] = {0, 0, 0};
  if (fabs(fa[0]) < largest_plain_f && fabs(fa[1]) < largest_plain_f &&
      fabs(fa[2]) < largest_plain_f) {
    if (f.single_image) {
      // An image within the cutoff has |f_a + S_a| <= reach < 1/2 on every periodic axis, so
      // it is the nearest one: one test, where the range below would enumerate (the same
      // pairs: the range holds at most this S, and any other S is farther than the cutoff).
      // i == j has only S = 0 here (its other images are more than twice the cutoff away).
      if (i == j) return 0;
      const int s[3] = {static_cast<int>(rint(-fa[0])), static_cast<int>(rint(-fa[1])),
                        static_cast<int>(rint(-fa[2]))};
      double r[3];
      image_vector(f, d, s[0], s[1], s[2], r);
      if (!(dot(r, r) < in.cutoff2)) return 0;
      visit(s);
      return 1;
    }
    // The bounds fit an int: no checks, and a loop of its own, since a branch inside the loop
    // below is compiled as both sides computed and one selected.
#pragma unroll
    for (int a = 0; a < 3; ++a) {
      if (!f.periodic[a]) continue;
      double low, high;
      shift_bounds(f, fa, a, low, high);
      first[a] = static_cast<int>(low);
      last[a] = static_cast<int>(high);
    }
    return visit_shifts(in, f, i, j, d, first, last, visit);
  }
  // Positions unwrapped past 10^8 boxes, or not finite (which their own rows report).
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    if (!f.periodic[a]) continue;
    double low, high;
    shift_bounds(f, fa, a, low, high);
    if (!shift_range(low, high, first[a], last[a])) return 0;
  }
  return visit_shifts(in, f, i, j, d, first, last, visit);
}

struct NoVisit {
  __host__ __device__ void operator()(const int*) const {}
};

// The first source of row i: its system's first particle, or i itself for half lists.
__host__ __device__ std::int64_t first_source(const Input& in, const Frame& f, std::int64_t i) {
  return in.half ? i : f.lo;
}

// ---- Cells (SourceSearch::cells) ------------------------------------------------------------
// Each system gets a grid over its particles' coordinates along the lattice axes, c_a = x . g[a]:
// periodic axes wrapped into [0, 1), open ones over the system's extent. A pair within the
// cutoff is less than reach[a] apart along axis a (|r . g[a]| <= |r| |g[a]|), so with cells at
// least that wide, plus the rounding of c_a, its particles lie in neighbouring cells (across
// the wrap on periodic axes). A periodic axis gets 1 cell or at least 3 (with 2, the cells
// before and after a row's own are the same one, and its sources would come twice). A system's
// cells are at most its particles, so system s's cells are numbered from its first particle lo
// on: one table of N cell starts serves every system, and no host ever needs their number.

// Order-preserving 64-bit image of a double: atomicMax over it is the maximum, whatever the
// order of the updates (so a system's extent is the same on every run).
__host__ __device__ inline unsigned long long ordered(double v) {
#ifdef __CUDA_ARCH__
  const auto b = static_cast<unsigned long long>(__double_as_longlong(v));
#else
  unsigned long long b;
  std::memcpy(&b, &v, sizeof b);
#endif
  return b >> 63 ? ~b : b | (1ull << 63);
}
__host__ __device__ inline double from_ordered(unsigned long long u) {
  const unsigned long long b = u >> 63 ? u & ~(1ull << 63) : ~u;
#ifdef __CUDA_ARCH__
  return __longlong_as_double(static_cast<long long>(b));
#else
  double v;
  std::memcpy(&v, &b, sizeof v);
  return v;
#endif
}

// Per system, at slot lo (its first particle), 9 maxima: of c_a, of -c_a, and of the size
// sum_k |x_k| |g[a][k]| that bounds c_a's rounding. 0 (below every ordered value) before.
constexpr int extent_words = 9;

// Row i's coordinate along axis a and the size that bounds its rounding.
__host__ __device__ inline double axis_coordinate(const Frame& f, int a, double& size) {
  size = fabs(f.xi[0] * f.g[a][0]) + fabs(f.xi[1] * f.g[a][1]) + fabs(f.xi[2] * f.g[a][2]);
  return f.xi[0] * f.g[a][0] + f.xi[1] * f.g[a][1] + f.xi[2] * f.g[a][2];
}

// A system's grid: cells per axis, and the map from a coordinate to a cell.
struct CellGrid {
  int m[3] = {1, 1, 1};
  double low[3] = {0, 0, 0};    // open axes: the extent's low end
  double scale[3] = {0, 0, 0};  // cells per unit of c_a
};

// The grid of row f's system, from its extents: the same on the host and the device, and for
// every row of the system (a function of the system's lattice, extents and size only).
__host__ __device__ inline CellGrid make_cell_grid(const Frame& f,
                                                   const unsigned long long* extents) {
  const unsigned long long* e = extents + extent_words * f.lo;
  const double particles = static_cast<double>(f.hi - f.lo);
  CellGrid grid;
  double m[3], span[3];
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    const double high = from_ordered(e[a]), low = -from_ordered(e[3 + a]);
    const double size = from_ordered(e[6 + a]);
    // A cell is reach[a] wide, plus a relative margin and the rounding of c_a at both ends
    // (each c_a within ~4e-16 of its size, the wrap and the scaling within an ulp of a cell).
    const double width = f.reach[a] * (1 + 1e-6) + 1e-14 * (1 + size);
    span[a] = f.periodic[a] ? 1.0 : high - low;
    grid.low[a] = f.periodic[a] ? 0.0 : low;
    double cells = span[a] / width;  // NaN or infinite for bad data: one cell below
    cells = cells >= 1 ? floor(fmin(cells, particles)) : 1;
    if (f.periodic[a] && cells < 3) cells = 1;
    m[a] = cells;
  }
  // At most one cell per particle: halve the most divided axis until the cells fit.
  while (m[0] * m[1] * m[2] > particles) {
    const int a = m[0] >= m[1] && m[0] >= m[2] ? 0 : (m[1] >= m[2] ? 1 : 2);
    const double halved = floor(m[a] / 2);
    m[a] = f.periodic[a] && halved < 3 ? 1 : fmax(halved, 1);
  }
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    grid.m[a] = static_cast<int>(m[a]);
    grid.scale[a] = span[a] > 0 ? m[a] / span[a] : 0;
  }
  return grid;
}

// The cell of coordinate c along axis a (periodic: wrapped first).
__host__ __device__ inline int cell_along(const Frame& f, const CellGrid& grid, int a, double c) {
  const double at = (f.periodic[a] ? c - floor(c) : c - grid.low[a]) * grid.scale[a];
  const int last = grid.m[a] - 1;
  if (!(at > 0)) return 0;  // NaN too: bad rows report their code
  return at < last ? static_cast<int>(at) : last;
}

// Row f's own cell, per axis.
__host__ __device__ inline void own_cell(const Frame& f, const CellGrid& grid, int cell[3]) {
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    double size;
    cell[a] = cell_along(f, grid, a, axis_coordinate(f, a, size));
  }
}

// A row's sources with cells: up to 18 runs of consecutive slots of the particles sorted by
// cell (per row of 3 cells along x, one run, or two across the wrap), walked as one list. The
// positions are read in the same sorted order, so a run's are consecutive in memory.
template <class Real>
struct CellSources {
  static constexpr int max_runs = 18;
  const std::uint32_t* sorted = nullptr;  // the particles by cell (stable: by index within one)
  const Real* sorted_xyz = nullptr;       // their positions, in that order
  std::int64_t half_from = 0;             // half lists: sources below the row are skipped
  int runs = 0;
  std::uint32_t first[max_runs], size[max_runs];
  std::uint32_t total = 0;

  __host__ __device__ void add(std::uint32_t begin, std::uint32_t end) {
    if (end <= begin) return;
    first[runs] = begin;
    size[runs] = end - begin;
    total += end - begin;
    ++runs;
  }
  // Where the k-th source is: a run and an offset in it; advanced by a team's stride at a time,
  // so that a walk costs a step per run, not a search per source.
  struct Cursor {
    int run = 0;
    std::uint32_t offset = 0;
  };
  __host__ __device__ void advance(Cursor& c, std::uint32_t by) const {
    c.offset += by;
    while (c.run < runs && c.offset >= size[c.run]) c.offset -= size[c.run++];
  }
  __host__ __device__ Cursor cursor(std::uint32_t k) const {
    Cursor c;
    advance(c, k);
    return c;
  }
  __host__ __device__ Source at(const Cursor& c) const {
    const std::uint32_t slot = first[c.run] + c.offset;
    Source s;
    // Both loads depend on the slot only: issued together, not one after the other.
    s.j = sorted[slot];
#pragma unroll
    for (int k = 0; k < 3; ++k) s.x[k] = static_cast<double>(sorted_xyz[3 * std::size_t(slot) + k]);
    if (s.j < half_from) s.j = -1;
    return s;
  }
};

// Where the cells live during a call (null pointers: all pairs).
struct CellTable {
  const unsigned long long* extents = nullptr;
  const std::uint32_t* sorted = nullptr;
  const std::uint32_t* starts = nullptr;
  const void* sorted_xyz = nullptr;  // Real, (N, 3), in sorted order
};

// The 27 cells around row f's own (fewer on axes of one cell, or at an open axis's ends), in a
// fixed order: z, then y, then x, each from -1 to +1.
template <class Real>
__host__ __device__ inline void gather_cell_sources(const Input& in, const Frame& f,
                                                    std::int64_t row, const CellTable& cells,
                                                    CellSources<Real>& out) {
  const CellGrid grid = make_cell_grid(f, cells.extents);
  int own[3];
  own_cell(f, grid, own);
  out.sorted = cells.sorted;
  out.sorted_xyz = static_cast<const Real*>(cells.sorted_xyz);
  out.half_from = in.half ? row : 0;
  const std::uint32_t* starts = cells.starts;
  const int mx = grid.m[0], my = grid.m[1];
  // Cells x0..x1 of the row (y, z) have consecutive numbers: one run of sorted slots (x1 + 1 is
  // the next row's first cell, or the system's last cell + 1: starts has N + 1 entries).
  const auto run = [&](int x0, int x1, int y, int z) {
    const std::int64_t row_cells = f.lo + (static_cast<std::int64_t>(z) * my + y) * mx;
    out.add(starts[row_cells + x0], starts[row_cells + x1 + 1]);
  };
  // The neighbouring cell d (-1, 0, 1) along axis a, or -1 where there is none.
  const auto step = [&](int a, int d) {
    if (grid.m[a] == 1) return d == 0 ? 0 : -1;
    const int c = own[a] + d;
    if (f.periodic[a]) return (c + grid.m[a]) % grid.m[a];
    return c >= 0 && c < grid.m[a] ? c : -1;
  };
  const int x = own[0];
  for (int dz = -1; dz <= 1; ++dz) {
    const int z = step(2, dz);
    if (z < 0) continue;
    for (int dy = -1; dy <= 1; ++dy) {
      const int y = step(1, dy);
      if (y < 0) continue;
      if (mx == 1) {
        run(0, 0, y, z);
      } else if (!f.periodic[0]) {
        run(x > 0 ? x - 1 : 0, x < mx - 1 ? x + 1 : mx - 1, y, z);
      } else if (x == 0) {  // across the wrap: the last cell, then cells 0 and 1
        run(mx - 1, mx - 1, y, z);
        run(0, 1, y, z);
      } else if (x == mx - 1) {  // the last two cells, then cell 0
        run(mx - 2, mx - 1, y, z);
        run(0, 0, y, z);
      } else {
        run(x - 1, x + 1, y, z);
      }
    }
  }
}

// The sources of a row with every particle of its system (SourceSearch::all_pairs): j ascending.
template <class Real>
struct SystemSources {
  const void* xyz = nullptr;
  std::int64_t first = 0;
  std::uint32_t total = 0;
  using Cursor = std::int64_t;  // the source itself
  __host__ __device__ Cursor cursor(std::uint32_t k) const { return first + k; }
  __host__ __device__ void advance(Cursor& c, std::uint32_t by) const { c += by; }
  __host__ __device__ Source at(Cursor j) const {
    Source s;
    s.j = j;
#pragma unroll
    for (int k = 0; k < 3; ++k) s.x[k] = load<Real>(xyz, 3 * j + k);
    return s;
  }
};

// Calls use(sources) with row f's sources, by cells or by system.
template <class Real, bool Cells, class Use>
__host__ __device__ inline void with_sources(const Input& in, const Frame& f, std::int64_t row,
                                             const CellTable& cells, Use&& use) {
  if constexpr (Cells) {
    CellSources<Real> sources;
    gather_cell_sources(in, f, row, cells, sources);
    use(sources);
  } else {
    const std::int64_t first = first_source(in, f, row);
    use(SystemSources<Real>{in.xyz, first, static_cast<std::uint32_t>(f.hi - first)});
  }
}

// The extents of every system (slot lo), for its grid.
// Row f's contribution to its system's extents: the ordered images of c_a, -c_a and c_a's
// rounding size (their maxima are the extents).
__host__ __device__ inline void extent_words_of(const Frame& f,
                                                unsigned long long (&word)[extent_words]) {
#pragma unroll
  for (int a = 0; a < 3; ++a) {
    double size;
    const double c = axis_coordinate(f, a, size);
    word[a] = ordered(c);
    word[3 + a] = ordered(-c);
    word[6 + a] = ordered(size);
  }
}

// Row f's cell number: its system's first particle plus its cell in the system's grid.
__host__ __device__ inline std::uint32_t cell_number(const Frame& f,
                                                     const unsigned long long* extents) {
  const CellGrid grid = make_cell_grid(f, extents);
  int c[3];
  own_cell(f, grid, c);
  return static_cast<std::uint32_t>(
      f.lo + (static_cast<std::int64_t>(c[2]) * grid.m[1] + c[1]) * grid.m[0] + c[0]);
}

// A warp whose particles are all of one system (most, but for a batch's boundaries) reduces its
// maxima first: one atomic per word and warp instead of 32 on the same address.
template <class Real>
__global__ void extents_kernel(Input in, const Lattice* lattices, unsigned long long* extents) {
  const std::int64_t i = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (in.run_if && *in.run_if == 0) return;  // the whole grid alike
  Frame f;
  const bool valid = i < in.n && make_frame<Real>(in, i, lattices, f) == 0;
  unsigned long long word[extent_words] = {};  // 0: below every ordered value
  if (valid) extent_words_of(f, word);
  const std::int64_t lo = valid ? f.lo : -1;
  const std::int64_t first_lo = __shfl_sync(all_lanes, lo, 0);
  if (__all_sync(all_lanes, lo == first_lo && valid)) {
#pragma unroll
    for (int w = 0; w < extent_words; ++w)
      for (int offset = warp_size / 2; offset > 0; offset /= 2)
        word[w] = max(word[w], __shfl_xor_sync(all_lanes, word[w], offset));
    if (threadIdx.x % warp_size != 0) return;
  } else if (!valid) {
    return;
  }
  unsigned long long* e = extents + extent_words * lo;
#pragma unroll
  for (int w = 0; w < extent_words; ++w) atomicMax(e + w, word[w]);
}

// Each particle's cell number (lo + its cell in the system's grid) and index, to be sorted.
template <class Real>
__global__ void cell_keys_kernel(Input in, const Lattice* lattices,
                                 const unsigned long long* extents, std::uint32_t* keys,
                                 std::uint32_t* index) {
  const std::int64_t i = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (i >= in.n) return;
  index[i] = static_cast<std::uint32_t>(i);
  keys[i] = static_cast<std::uint32_t>(i);  // bad rows: their own number; the count reports them
  if (in.run_if && *in.run_if == 0) return;
  Frame f;
  if (make_frame<Real>(in, i, lattices, f)) return;
  keys[i] = cell_number(f, extents);
}

// starts[b]: the first sorted slot whose cell number is >= b, for b in [0, n]; and the
// positions in sorted order (slot b < n).
template <class Real>
__global__ void cell_starts_kernel(const Input in, const std::uint32_t* sorted_keys,
                                   const std::uint32_t* sorted, std::uint32_t* starts,
                                   Real* sorted_xyz) {
  const std::int64_t b = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const std::int64_t n = in.n;
  if (b > n) return;
  std::int64_t lo = 0, hi = n;
  while (lo < hi) {
    const std::int64_t mid = lo + (hi - lo) / 2;
    if (sorted_keys[mid] < static_cast<std::uint64_t>(b))
      lo = mid + 1;
    else
      hi = mid;
  }
  starts[b] = static_cast<std::uint32_t>(lo);
  if (b == n) return;
  const Real* xyz = static_cast<const Real*>(in.xyz);
#pragma unroll
  for (int k = 0; k < 3; ++k) sorted_xyz[3 * b + k] = xyz[3 * std::int64_t(sorted[b]) + k];
}

// A row's team: `Threads` lanes of one warp (a power of two up to 32; a warp holds 32 / Threads
// teams side by side) or the whole block (Threads = block_threads, one row per block). Few rows
// get a block each, so that the GPU has enough warps to hide the latency of the pair tests
// (rows_for_block_teams); many rows of small systems get a few lanes each (row_team_threads), so
// that a row's sources fill its lanes and its fixed costs are shared by fewer lanes.
template <int Threads>
struct Team {
  static constexpr int threads = Threads;
  static constexpr bool whole_block = Threads == block_threads;
  static_assert(whole_block || (Threads <= warp_size && warp_size % Threads == 0),
                "a team is a power of two of a warp's lanes, or the whole block");
  static constexpr int width = whole_block ? warp_size : Threads;  // of its shuffles
  __device__ static std::int64_t row() {
    return (std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x) / threads;
  }
  __device__ static int rank() { return threadIdx.x % threads; }
  // The team's lanes of its warp: teams that share a warp shuffle and wait apart.
  __device__ static unsigned lanes() {
    if constexpr (width == warp_size)
      return all_lanes;
    else
      return ((1u << width) - 1) << (threadIdx.x % warp_size / width * width);
  }
  // The team's sum of v, in every thread.
  __device__ static unsigned long long sum(unsigned long long v) {
    for (int offset = width / 2; offset > 0; offset /= 2)
      v += __shfl_xor_sync(lanes(), v, offset, width);
    if constexpr (whole_block) {
      __shared__ unsigned long long warp_sums[block_warps];
      __syncthreads();  // the last call's sums are read
      if (threadIdx.x % warp_size == 0) warp_sums[threadIdx.x / warp_size] = v;
      __syncthreads();
      v = 0;
#pragma unroll
      for (int w = 0; w < block_warps; ++w) v += warp_sums[w];
    }
    return v;
  }
  // The team's inclusive scan of v in rank order, and its total.
  __device__ static std::uint32_t scan(std::uint32_t v, std::uint32_t& total) {
    const int lane = threadIdx.x % width;
    for (int offset = 1; offset < width; offset *= 2) {
      const std::uint32_t other = __shfl_up_sync(lanes(), v, offset, width);
      if (lane >= offset) v += other;
    }
    total = __shfl_sync(lanes(), v, width - 1, width);
    if constexpr (whole_block) {
      __shared__ std::uint32_t warp_totals[block_warps];
      __syncthreads();  // the last call's totals are read
      if (lane == warp_size - 1) warp_totals[threadIdx.x / warp_size] = v;
      __syncthreads();
      const int warp = threadIdx.x / warp_size;
      std::uint32_t before = 0;
      total = 0;
#pragma unroll
      for (int w = 0; w < block_warps; ++w) {
        if (w < warp) before += warp_totals[w];
        total += warp_totals[w];
      }
      v += before;
    }
    return v;
  }
  __device__ static void sync() {
    if constexpr (whole_block)
      __syncthreads();
    else
      __syncwarp(lanes());
  }
};

// What a team without a row (past the last, in the last tile of list_rows) gets as its code.
constexpr int no_row = 1;

// Row `row`'s frame, made once by its team's first thread into shared memory (code: make_frame's,
// with bad rows reported to status; no_row past the last row), for every thread of the team to
// read: held in registers, the frame took about 60 of the ~126 registers a thread had, which
// left a quarter of the warps a multiprocessor can run. Every thread of the team calls it.
template <class Real, int Threads>
__device__ const Frame& team_frame(const Input& in, std::int64_t row, const Lattice* lattices,
                                   int* status, int& code) {
  using T = Team<Threads>;
  constexpr int teams = block_threads / T::threads;
  // Raw storage: a __shared__ array cannot have Frame's default member initializers.
  __shared__ alignas(Frame) unsigned char frames[teams * sizeof(Frame)];
  __shared__ int codes[teams];
  const int team = threadIdx.x / T::threads;
  Frame* const frame = reinterpret_cast<Frame*>(frames) + team;
  if (T::rank() == 0) {
    Frame made;
    codes[team] = row < in.n ? make_frame<Real>(in, row, lattices, made) : no_row;
    new (frame) Frame(made);
    if (codes[team] < 0 && status) atomicMin(status, codes[team]);
  }
  T::sync();
  code = codes[team];
  return *frame;
}

// The row of team k: with cells, the particles in cell order, so that the teams of a block (and
// of the blocks beside it) walk the same cells and find their sources in cache. Each row writes
// only its own count and entries, so the order the rows run in changes no result.
template <bool Cells>
__device__ std::int64_t team_row(std::int64_t k, const Input& in, const CellTable& cells) {
  if constexpr (Cells) return k < in.n ? std::int64_t(cells.sorted[k]) : k;
  return k;
}

// The rounds of a row's walk (a source per thread each) whose source a thread found within the
// cutoff, as bits: the fill that follows the count in one launch tests only those again. Rounds
// past the 32nd have no bit and are always tested.
constexpr std::uint32_t every_round = ~0u;
__device__ inline bool round_hit(std::uint32_t hit_rounds, std::uint32_t round) {
  return round >= 32 || (hit_rounds >> round & 1u);
}

// The one image of a source that has one, as the count of the one-launch pass found it, kept for
// that launch's write: a word per thread and round in shared memory for the first `rounds`
// rounds, S_a + 512 in 10 bits each and a bit that says it is there. The write then neither loads
// that source nor tests it again (the same test, so the same pairs); a source with several
// images, or a shift past 511, is tested again as before. Null words: nothing is kept.
struct StagedImages {
  static constexpr std::uint32_t rounds = 8;
  static constexpr std::uint32_t kept = 1u << 31;
  std::uint32_t* words = nullptr;  // [rounds][block_threads]
  __device__ static std::uint32_t pack(const int* s) {
    std::uint32_t word = kept;
#pragma unroll
    for (int a = 0; a < 3; ++a) {
      if (s[a] < -512 || s[a] > 511) return 0;
      word |= static_cast<std::uint32_t>(s[a] + 512) << (10 * a);
    }
    return word;
  }
  __device__ void put(std::uint32_t round, std::uint32_t word) const {
    if (words && round < rounds) words[round * block_threads + threadIdx.x] = word;
  }
  // This thread's image of round `round` into s, if it was kept.
  __device__ bool take(std::uint32_t round, int* s) const {
    if (!words || round >= rounds) return false;
    const std::uint32_t word = words[round * block_threads + threadIdx.x];
#pragma unroll
    for (int a = 0; a < 3; ++a) s[a] = static_cast<int>(word >> (10 * a) & 1023u) - 512;
    return (word & kept) != 0;
  }
};

// Row `row`'s pairs, from its frame f, in every thread of its team; hit_rounds: this thread's.
template <class Real, int Threads, bool Cells>
__device__ unsigned long long count_row(const Input& in, const Frame& f, std::int64_t row,
                                        const CellTable& cells, std::uint32_t& hit_rounds,
                                        StagedImages staged = {}) {
  using T = Team<Threads>;
  unsigned long long c = 0;
  hit_rounds = 0;
  with_sources<Real, Cells>(in, f, row, cells, [&](const auto& sources) {
    auto at = sources.cursor(T::rank());
    std::uint32_t round = 0;
    // With cells, the next round's source is loaded before this round's is tested, so that its
    // load's latency is spent on the test: 0.93x the time at 4,000 particles on an H100. The
    // one-launch pass (all pairs), held to 64 registers, lost 1 % with it at 256 x 100.
    Source next = Cells && T::rank() < sources.total ? sources.at(at) : Source{};
    for (std::uint32_t k = T::rank(); k < sources.total; k += T::threads, ++round) {
      Source source;
      if constexpr (Cells) {
        source = next;
        sources.advance(at, T::threads);
        if (k + T::threads < sources.total) next = sources.at(at);
      } else {
        source = sources.at(at);
        sources.advance(at, T::threads);
      }
      std::uint32_t hits = 0;
      if constexpr (Cells) {
        hits = source.j >= 0 ? for_each_image(in, f, row, source, NoVisit{}) : 0;
      } else {
        std::uint32_t image = 0;
        if (source.j >= 0)
          hits = for_each_image(in, f, row, source,
                                [&](const int* s) { image = StagedImages::pack(s); });
        staged.put(round, hits == 1 ? image : 0);
      }
      c += hits;
      if (hits && round < 32) hit_rounds |= 1u << round;
    }
  });
  return T::sum(c);
}

template <class Real, int Threads, bool Cells>
__global__ __launch_bounds__(block_threads) void count_rows(Input in, const Lattice* lattices,
                                                            CellTable cells,
                                                            unsigned long long* counts,
                                                            int* status) {
  using T = Team<Threads>;
  const std::int64_t row = team_row<Cells>(T::row(), in, cells);
  // Whole teams leave together: their bounds are the row's.
  if (row >= in.n || (in.run_if && *in.run_if == 0)) return;
  int bad;
  const Frame& f = team_frame<Real, Threads>(in, row, lattices, status, bad);
  if (bad) return;
  std::uint32_t hit_rounds;  // unused: the fill is another launch
  const unsigned long long c = count_row<Real, Threads, Cells>(in, f, row, cells, hit_rounds);
  if (T::rank() == 0) counts[row] = c;
}

// Where row `row`'s list lies: its first entry (s * capacity for system s with a list per
// system, else 0) and the global offset its list counts from (`origin`: its system's first
// row's offset).
struct ListSlots {
  std::uint64_t first = 0;
  unsigned long long origin = 0;
};
__host__ __device__ ListSlots list_slots(const Input& in, std::int64_t row,
                                         unsigned long long origin, const StaticPairs& out) {
  if (in.systems == 0) return {};
  const std::int64_t system = in.batch ? in.batch[row] : 0;
  return {static_cast<std::uint64_t>(system) * out.capacity, origin};
}

// Writes row `row`'s pairs from entry first + start on (start counted within its list), up to the
// capacity; a thread tests only the rounds of hit_rounds (count_row's, or every_round).
template <class Real, int Threads, bool Cells>
__device__ void fill_row(const Input& in, const Frame& f, std::int64_t row, const CellTable& cells,
                         std::uint64_t first, unsigned long long start, const StaticPairs& out,
                         std::uint32_t hit_rounds, StagedImages staged = {}) {
  using T = Team<Threads>;
  const int rank = T::rank();
  unsigned long long written = start;
  // Chunks of one source per thread in lockstep: each thread's hits go after the lower ranks'
  // (a team scan), so the order is the sources' whatever the scheduling. Every thread of the
  // team takes every chunk (the scan waits for all of them).
  with_sources<Real, Cells>(in, f, row, cells, [&](const auto& sources) {
    auto cursor = sources.cursor(rank);
    std::uint32_t round = 0;
    for (std::uint32_t base = 0; base < sources.total;
         base += T::threads, sources.advance(cursor, T::threads), ++round) {
      const bool tested = base + rank < sources.total && round_hit(hit_rounds, round);
      // The first image is kept from the counting test: most sources have at most one, and only
      // those with more are tested again.
      int image[3] = {0, 0, 0};
      Source source;
      std::uint32_t hits = 0;
      if constexpr (!Cells) {
        if (tested && staged.take(round, image)) {  // the count's one image, j the cursor
          source.j = cursor;
          hits = 1;
        }
      }
      if (tested && hits == 0) {
        source = sources.at(cursor);
        if (source.j >= 0)
          hits = for_each_image(in, f, row, source, [&](const int* s) {
            image[0] = s[0];
            image[1] = s[1];
            image[2] = s[2];
          });
      }
      const std::int64_t j = source.j;
      std::uint32_t chunk = 0;
      const std::uint32_t before = T::scan(hits, chunk) - hits;
      unsigned long long at = written + before;
      const auto write = [&](const int* s) {
        if (at < static_cast<unsigned long long>(out.capacity)) {
          const std::uint64_t e = first + at;
          out.i[e] = row;
          out.j[e] = j;
          if (out.shifts)
            for (int k = 0; k < 3; ++k) out.shifts[3 * e + k] = s[k];
        }
        ++at;
      };
      if (hits == 1)
        write(image);
      else if (hits > 1)
        for_each_image(in, f, row, source, write);
      written += chunk;
      if (written >= static_cast<unsigned long long>(out.capacity)) return;
    }
  });
}

template <class Real, int Threads, bool Cells>
__global__ __launch_bounds__(block_threads) void fill_rows(Input in, const Lattice* lattices,
                                                           CellTable cells,
                                                           const unsigned long long* offsets,
                                                           StaticPairs out) {
  using T = Team<Threads>;
  const std::int64_t row = team_row<Cells>(T::row(), in, cells);
  if (row >= in.n || (in.run_if && *in.run_if == 0)) return;
  int bad;
  const Frame& f = team_frame<Real, Threads>(in, row, lattices, nullptr, bad);
  if (bad) return;  // the count reported it
  // A list per system: this system's entries from s * capacity, counted from its first row.
  const ListSlots slots = list_slots(in, row, in.systems ? offsets[f.lo] : 0, out);
  const unsigned long long start = offsets[row] - slots.origin;
  if (start >= static_cast<unsigned long long>(out.capacity) || offsets[row + 1] == offsets[row])
    return;
  fill_row<Real, Threads, Cells>(in, f, row, cells, slots.first, start, out, every_round);
}

// ---- All pairs in one launch: count, offset, fill ----------------------------------------------
// Without cells the rows run in index order, so one launch can count a row, find where its pairs
// start, and write them. The rows go in tiles: a warp's teams' rows (32 / Threads consecutive
// rows), or a block's one row. Each tile takes the next tile number from a ticket counter (so
// every earlier tile is running or done) and finds its offset by a decoupled look-back (Merrill
// and Garland, "Single-pass Parallel Prefix Scan with Decoupled Look-back", 2016): a word per
// tile, first its count, then its inclusive prefix. That replaces a count launch and a two-launch
// scan, which at a thousand particles were more of the call than the pair tests; the fill tests
// again, from L1, only the sources that the count found within the cutoff (round_hit).
constexpr unsigned long long tile_counted = 1ull << 62, tile_prefixed = 1ull << 63;
constexpr unsigned long long tile_value = tile_counted - 1;

__device__ inline unsigned long long load_volatile(const unsigned long long* p) {
  return *static_cast<const volatile unsigned long long*>(p);
}
__device__ inline void store_volatile(unsigned long long* p, unsigned long long v) {
  *static_cast<volatile unsigned long long*>(p) = v;
}
// A tile's prefix, published after its offsets (release), and read before them (acquire): a
// fence of its own, lighter than __threadfence's sequentially consistent one.
using DeviceWord = cuda::atomic_ref<unsigned long long, cuda::thread_scope_device>;
__device__ inline void store_release(unsigned long long* p, unsigned long long v) {
  DeviceWord(*p).store(v, cuda::memory_order_release);
}
__device__ inline unsigned long long load_acquire(unsigned long long* p) {
  return DeviceWord(*p).load(cuda::memory_order_acquire);
}
// Between polls of a word that another tile has yet to write: a pause, growing, that leaves the
// issue slots to the warps still counting (a fifth of the samples were this spin without it).
struct Backoff {
  unsigned ns = 32;
  __device__ void pause() {
    __nanosleep(ns);
    if (ns < 512) ns *= 2;
  }
};

// The pairs before `tile` (whose own are `count`), in every lane of the calling warp, which
// publishes the tile's count first: the warp reads 32 earlier words at a time, nearest first,
// until one holds a prefix (before tile 0, a prefix of 0).
__device__ unsigned long long look_back(unsigned long long* words, std::int64_t tile,
                                        unsigned long long count) {
  const int lane = threadIdx.x % warp_size;
  if (lane == 0) store_volatile(words + tile, tile_counted | count);
  unsigned long long before = 0;
  for (std::int64_t end = tile;; end -= warp_size) {
    const std::int64_t k = end - 1 - lane;
    unsigned long long word = tile_prefixed;
    if (k >= 0) {
      Backoff backoff;
      while (((word = load_volatile(words + k)) & ~tile_value) == 0) backoff.pause();
    }
    const unsigned prefixed = __ballot_sync(all_lanes, (word & tile_prefixed) != 0);
    const int nearest = prefixed ? __ffs(static_cast<int>(prefixed)) - 1 : warp_size;
    unsigned long long v = lane <= nearest ? word & tile_value : 0;
    for (int offset = warp_size / 2; offset > 0; offset /= 2)
      v += __shfl_xor_sync(all_lanes, v, offset);
    before += v;
    if (prefixed) return before;
  }
}

// The tile's rows, their pairs and where they go. Teams past the last row count none and write
// nothing, but take part in their warp's scan and look-back.
template <class Real, int Threads>
__global__ __launch_bounds__(block_threads, list_rows_blocks_per_multiprocessor) void list_rows(
    Input in, const Lattice* lattices, unsigned long long* words, unsigned long long* offsets,
    int* status, StaticPairs out) {
  using T = Team<Threads>;
  if (in.run_if && *in.run_if == 0) return;  // the whole grid alike
  constexpr int tile_threads = T::whole_block ? block_threads : warp_size;
  constexpr int tile_rows = T::whole_block ? 1 : warp_size / Threads;
  constexpr int tiles = block_threads / tile_threads;
  __shared__ std::int64_t tile_numbers[tiles];
  __shared__ unsigned long long block_before;  // whole-block teams: the row's offset
  const int tile_in_block = threadIdx.x / tile_threads;
  const int lane = threadIdx.x % warp_size;
  if (threadIdx.x % tile_threads == 0)
    tile_numbers[tile_in_block] = static_cast<std::int64_t>(atomicAdd(words + in.n, 1ull));
  if constexpr (T::whole_block)
    __syncthreads();
  else
    __syncwarp();
  const std::int64_t tile = tile_numbers[tile_in_block];
  const std::int64_t row = tile * tile_rows + (threadIdx.x % tile_threads) / Threads;
  if (tile * tile_rows >= in.n) return;  // whole tiles
  int bad;
  const Frame& f = team_frame<Real, Threads>(in, row, lattices, status, bad);
  __shared__ std::uint32_t staged_words[StagedImages::rounds * block_threads];
  const StagedImages staged{staged_words};
  std::uint32_t hit_rounds = 0;
  const unsigned long long count =
      bad ? 0ull : count_row<Real, Threads, false>(in, f, row, CellTable{}, hit_rounds, staged);
  // The teams' counts before this one in the tile (every lane of a team holds its count), and
  // the tile's total.
  unsigned long long in_tile = count;
  for (int offset = T::width; offset < warp_size; offset *= 2) {
    const unsigned long long other = __shfl_up_sync(all_lanes, in_tile, offset);
    if (lane >= offset) in_tile += other;
  }
  const unsigned long long tile_count = __shfl_sync(all_lanes, in_tile, warp_size - 1);
  in_tile -= count;
  unsigned long long before = 0;
  if (threadIdx.x % tile_threads < warp_size) {  // the tile's first warp
    const unsigned long long tile_before = look_back(words, tile, tile_count);
    before = tile_before + in_tile;
    if (T::rank() == 0 && row < in.n) {  // bad rows too: their systems' counts need them
      offsets[row] = before;
      if (row + 1 == in.n) offsets[in.n] = before + count;
    }
    if constexpr (T::whole_block) block_before = before;
    __syncwarp();
    if (lane == 0)  // after the tile's offsets (the warp's, ordered by __syncwarp)
      store_release(words + tile, tile_prefixed | (tile_before + tile_count));
    __syncwarp();
  }
  if constexpr (T::whole_block) {
    __syncthreads();
    before = block_before;
  }
  if (bad || count == 0 || out.capacity == 0) return;
  // A list per system: its entries from s * capacity, counted from its first row's offset, which
  // that row's tile (this one, or an earlier one, so running or done) publishes before its
  // prefix.
  unsigned long long origin = before;
  if (in.systems && f.lo != row) {
    Backoff backoff;
    while ((load_acquire(words + f.lo / tile_rows) & tile_prefixed) == 0) backoff.pause();
    origin = load_volatile(offsets + f.lo);
  }
  const ListSlots slots = list_slots(in, row, origin, out);
  const unsigned long long start = before - slots.origin;
  if (start >= static_cast<unsigned long long>(out.capacity)) return;
  fill_row<Real, Threads, false>(in, f, row, CellTable{}, slots.first, start, out, hit_rounds,
                                 staged);
}

// The count (or the first error code), and padding from the count to the capacity.
__global__ void finish(const unsigned long long* total, const int* status, const int* run_if,
                       StaticPairs out) {
  if (run_if && *run_if == 0) return;
  const bool bad = *status < 0;
  const unsigned long long pairs = bad ? 0 : *total;
  const auto capacity = static_cast<std::int64_t>(out.capacity);
  const std::int64_t first = static_cast<std::int64_t>(
      pairs < static_cast<unsigned long long>(capacity) ? pairs : capacity);
  const std::int64_t thread = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  if (thread == 0) *out.count = bad ? std::int64_t(*status) : static_cast<std::int64_t>(pairs);
  for (std::int64_t e = first + thread; e < capacity; e += std::int64_t(gridDim.x) * blockDim.x) {
    out.i[e] = out.j[e] = out.pad_index;
    if (out.shifts)
      for (int k = 0; k < 3; ++k) out.shifts[3 * e + k] = 0;
  }
}

// finish for a list per system: each system's count (offsets at its last row minus its first,
// or the error code) and padding after its pairs in its own slots.
__global__ void finish_systems(Input in, const unsigned long long* offsets, const int* status,
                               StaticPairs out) {
  if (in.run_if && *in.run_if == 0) return;
  const bool bad = *status < 0;
  const std::uint64_t entries = out.capacity * out.systems;
  const std::int64_t thread = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x;
  const std::int64_t stride = std::int64_t(gridDim.x) * blockDim.x;
  for (std::int64_t s = thread; s < std::int64_t(out.systems); s += stride) {
    const std::int64_t lo = in.batch ? bound(in.batch, in.n, s, false) : (s == 0 ? 0 : in.n);
    const std::int64_t hi = in.batch ? bound(in.batch, in.n, s, true) : in.n;
    out.count[s] = bad ? std::int64_t(*status) : std::int64_t(offsets[hi] - offsets[lo]);
  }
  for (std::int64_t e = thread; e < std::int64_t(entries); e += stride) {
    const std::int64_t s = e / std::int64_t(out.capacity);
    const std::int64_t lo = in.batch ? bound(in.batch, in.n, s, false) : (s == 0 ? 0 : in.n);
    const std::int64_t hi = in.batch ? bound(in.batch, in.n, s, true) : in.n;
    const auto pairs = static_cast<std::int64_t>(offsets[hi] - offsets[lo]);
    if (!bad && e - s * std::int64_t(out.capacity) < pairs) continue;
    out.i[e] = out.j[e] = out.pad_index;
    if (out.shifts)
      for (int k = 0; k < 3; ++k) out.shifts[3 * e + k] = 0;
  }
}

// The largest capacity of a pair list, far beyond any device's memory: below it, the byte sizes
// of StaticPairBuffer and the indices 3 * entry of S stay far from overflowing.
constexpr std::size_t max_capacity = std::size_t(1) << 56;

constexpr std::size_t align_up(std::size_t bytes) {
  return (bytes + 255) / 256 * 256;
}

void* allocate(const Context& ctx, std::size_t bytes) {
  if (ctx.memory) return ctx.memory->allocate(bytes, ctx.stream);
  return detail::cuda::pooled_allocate_async(bytes, static_cast<cudaStream_t>(ctx.stream));
}

void deallocate(const Context& ctx, void* p, std::size_t bytes) noexcept {
  if (!p) return;
  if (ctx.memory)
    ctx.memory->deallocate(p, bytes, ctx.stream);
  else
    cudaFreeAsync(p, static_cast<cudaStream_t>(ctx.stream));
}

void require(bool ok, const std::string& what) {
  if (!ok) throw Error(ErrorCode::invalid_argument, "list_pairs_small_systems: " + what);
}

// The pass's arguments, checked on the host (before any work).
Input make_input(const DeviceSystems& systems, double cutoff, const PairOptions& options,
                 const StaticPairs& out) {
  detail::validate_cutoff_value(cutoff);
  const std::size_t n = systems.size;
  require(n < (std::size_t(1) << 32), "at most 2^32 - 1 particles, got " + std::to_string(n));
  require(n == 0 || systems.positions,
          "positions are null for " + std::to_string(n) + " particles");
  require(!systems.cells || systems.cell_count >= 1, "cells given with cell_count 0");
  require(!systems.pbc || systems.pbc_count >= 1, "pbc given with pbc_count 0");
  require(!systems.pbc || systems.cells, "pbc without cells: periodic rows need their vectors");
  require(systems.batch || (systems.cell_count <= 1 && systems.pbc_count <= 1),
          "several cells or pbc rows but no batch: which system has which?");
  require(out.count, "the count pointer is null");
  require(out.capacity == 0 || (out.i && out.j),
          "i or j is null for a capacity of " + std::to_string(out.capacity));
  require(out.capacity <= max_capacity,
          "capacity " + std::to_string(out.capacity) + " is above the largest, 2^56");
  require(out.systems == 0 || out.capacity == 0 || out.systems <= max_capacity / out.capacity,
          "capacity " + std::to_string(out.capacity) + " for each of " +
              std::to_string(out.systems) + " systems is above the largest, 2^56 in all");
  require(out.systems <= 1 || n == 0 || systems.batch,
          "a list per system for " + std::to_string(out.systems) + " systems needs the batch");

  Input in;
  in.xyz = systems.positions;
  in.n = static_cast<std::int64_t>(n);
  in.cells = systems.cells;
  in.cell_count = static_cast<std::int64_t>(systems.cells ? systems.cell_count : 0);
  in.pbc = systems.pbc;
  in.pbc_count = static_cast<std::int64_t>(systems.pbc ? systems.pbc_count : 0);
  in.batch = systems.batch;
  in.cutoff = cutoff;
  in.cutoff2 = cutoff * cutoff;
  in.half = options.half;
  in.run_if = options.run_if;
  in.systems = static_cast<std::int64_t>(out.systems);
  const std::size_t known_systems = std::max({out.systems, systems.cells ? systems.cell_count : 0,
                                              systems.pbc ? systems.pbc_count : 0, std::size_t(1)});
  in.by_cells =
      options.search == SourceSearch::cells || (options.search == SourceSearch::automatic &&
                                                small_pass_uses_cells(systems.size, known_systems));
  return in;
}

// The cells of a call on the host, as the kernels make them: extents, then each particle's cell
// number, a stable sort by it, and the first slot of every cell number.
template <class Real>
struct HostCells {
  std::vector<unsigned long long> extents;
  std::vector<std::uint32_t> sorted, starts;
  std::vector<Real> sorted_xyz;
  HostCells(const Input& in, const std::vector<Lattice>& lattices) {
    const auto n = static_cast<std::size_t>(in.n);
    extents.assign(extent_words * n, 0);
    for (std::int64_t i = 0; i < in.n; ++i) {
      Frame f;
      if (make_frame<Real>(in, i, lattices.data(), f)) continue;
      unsigned long long word[extent_words];
      extent_words_of(f, word);
      unsigned long long* e = extents.data() + extent_words * f.lo;
      for (int w = 0; w < extent_words; ++w) e[w] = std::max(e[w], word[w]);
    }
    std::vector<std::uint32_t> keys(n);
    for (std::int64_t i = 0; i < in.n; ++i) {
      keys[i] = static_cast<std::uint32_t>(i);
      Frame f;
      if (make_frame<Real>(in, i, lattices.data(), f)) continue;
      keys[i] = cell_number(f, extents.data());
    }
    sorted.resize(n);
    for (std::size_t i = 0; i < n; ++i) sorted[i] = static_cast<std::uint32_t>(i);
    std::stable_sort(sorted.begin(), sorted.end(),
                     [&](std::uint32_t a, std::uint32_t b) { return keys[a] < keys[b]; });
    starts.resize(n + 1);
    std::size_t slot = 0;
    for (std::size_t b = 0; b <= n; ++b) {
      while (slot < n && keys[sorted[slot]] < b) ++slot;
      starts[b] = static_cast<std::uint32_t>(slot);
    }
    const Real* xyz = static_cast<const Real*>(in.xyz);
    sorted_xyz.resize(3 * n);
    for (std::size_t p = 0; p < n; ++p)
      for (int k = 0; k < 3; ++k) sorted_xyz[3 * p + k] = xyz[3 * std::size_t(sorted[p]) + k];
  }
  CellTable table() const {
    return {extents.data(), sorted.data(), starts.data(), sorted_xyz.data()};
  }
};

// The same enumeration, row after row on the host, in the same order and with the same codes:
// what lets a machine without a GPU test the pass's arithmetic (cuda/device_pairs_host.hpp).
template <class Real, bool Cells>
void host_pass(const Input& in, const StaticPairs& out) {
  if (in.run_if && *in.run_if == 0) return;
  const std::size_t lists = out.systems ? out.systems : 1;
  std::vector<std::uint64_t> written(lists, 0);  // by list
  std::vector<Lattice> lattices(static_cast<std::size_t>(lattice_count(in)));
  for (std::size_t s = 0; s < lattices.size(); ++s)
    make_lattice<Real>(in, static_cast<std::int64_t>(s), lattices[s]);
  CellTable cells;
  std::vector<HostCells<Real>> made;  // only with Cells
  if (Cells) cells = made.emplace_back(in, lattices).table();
  int status = 0;
  for (std::int64_t row = 0; row < in.n; ++row) {
    Frame f;
    if (const int bad = make_frame<Real>(in, row, lattices.data(), f)) {
      status = std::min(status, bad);
      continue;
    }
    const std::size_t list = out.systems && in.batch ? std::size_t(in.batch[row]) : 0;
    std::uint64_t& at = written[list];
    with_sources<Real, Cells>(in, f, row, cells, [&](const auto& sources) {
      auto cursor = sources.cursor(0);
      for (std::uint32_t k = 0; k < sources.total; ++k, sources.advance(cursor, 1)) {
        const Source source = sources.at(cursor);
        const std::int64_t j = source.j;
        if (j < 0) continue;
        for_each_image(in, f, row, source, [&](const int* s) {
          if (at < out.capacity) {
            const std::uint64_t e = list * out.capacity + at;
            out.i[e] = row;
            out.j[e] = j;
            if (out.shifts)
              for (int k = 0; k < 3; ++k) out.shifts[3 * e + k] = s[k];
          }
          ++at;
        });
      }
    });
  }
  for (std::size_t list = 0; list < lists; ++list) {
    const std::uint64_t kept =
        status < 0 ? 0 : std::min<std::uint64_t>(written[list], out.capacity);
    for (std::uint64_t e = list * out.capacity + kept; e < (list + 1) * out.capacity; ++e) {
      out.i[e] = out.j[e] = out.pad_index;
      if (out.shifts)
        for (int k = 0; k < 3; ++k) out.shifts[3 * e + k] = 0;
    }
    out.count[list] = status < 0 ? std::int64_t(status) : static_cast<std::int64_t>(written[list]);
  }
}

template <class Real>
void host_pass(const Input& in, const StaticPairs& out) {
  if (in.by_cells)
    host_pass<Real, true>(in, out);
  else
    host_pass<Real, false>(in, out);
}

}  // namespace

namespace {

// The row passes with teams of Threads: without cells one launch (list_rows); with cells, count
// per row, the scan into offsets, fill (the rows run in cell order, for the cache, so no row
// can wait for the one before it). Many rows of all pairs in three launches instead (count_rows
// and fill_rows serve both) measured no faster at 256 x 100 (159 us either way) and slower at
// 512 x 128 (266 against 239): a scan and a launch cost what the look-back's waits did.
template <class Real, bool Cells, int Threads>
void row_passes_of(const Input& in, const Lattice* lattices, const CellTable& cells,
                   unsigned long long* counts, int* status, unsigned long long* offsets,
                   void* scan_storage, std::size_t scan_bytes, const StaticPairs& out,
                   cudaStream_t stream) {
  const auto n = static_cast<std::size_t>(in.n);
  const auto blocks = static_cast<unsigned>((n * Threads + block_threads - 1) / block_threads);
  if constexpr (!Cells) {
    if (n > 0) {
      list_rows<Real, Threads>
          <<<blocks, block_threads, 0, stream>>>(in, lattices, counts, offsets, status, out);
      RAYCUT_CUDA_CHECK_LAUNCH();
    }
    return;
  }
  if (n > 0) {
    count_rows<Real, Threads, Cells>
        <<<blocks, block_threads, 0, stream>>>(in, lattices, cells, counts, status);
    RAYCUT_CUDA_CHECK_LAUNCH();
  }
  RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(scan_storage, scan_bytes, counts, offsets,
                                                  static_cast<std::int64_t>(n + 1), stream));
  if (n > 0 && out.capacity > 0) {
    fill_rows<Real, Threads, Cells>
        <<<blocks, block_threads, 0, stream>>>(in, lattices, cells, offsets, out);
    RAYCUT_CUDA_CHECK_LAUNCH();
  }
}

template <class Real, bool Cells>
void row_passes(const Input& in, const Lattice* lattices, const CellTable& cells,
                unsigned long long* counts, int* status, unsigned long long* offsets,
                void* scan_storage, std::size_t scan_bytes, const StaticPairs& out,
                cudaStream_t stream) {
  switch (row_team_threads(static_cast<std::size_t>(in.n))) {
    case block_threads:
      return row_passes_of<Real, Cells, block_threads>(in, lattices, cells, counts, status, offsets,
                                                       scan_storage, scan_bytes, out, stream);
    case warp_size:
      return row_passes_of<Real, Cells, warp_size>(in, lattices, cells, counts, status, offsets,
                                                   scan_storage, scan_bytes, out, stream);
    case 16:
      return row_passes_of<Real, Cells, 16>(in, lattices, cells, counts, status, offsets,
                                            scan_storage, scan_bytes, out, stream);
    default:
      return row_passes_of<Real, Cells, 8>(in, lattices, cells, counts, status, offsets,
                                           scan_storage, scan_bytes, out, stream);
  }
}

// The cells of every system (SourceSearch::cells): extents, cell numbers, a stable radix sort of
// the particles by them, and the first slot of every cell number.
template <class Real>
void make_cells(const Input& in, const Lattice* lattices, unsigned long long* extents,
                std::uint32_t* keys, std::uint32_t* sorted_keys, std::uint32_t* index,
                std::uint32_t* sorted, std::uint32_t* starts, void* sorted_xyz, void* sort_storage,
                std::size_t sort_bytes, int key_bits, cudaStream_t stream) {
  const auto n = static_cast<std::size_t>(in.n);
  const auto blocks = static_cast<unsigned>((n + 255) / 256);
  extents_kernel<Real><<<blocks, 256, 0, stream>>>(in, lattices, extents);
  RAYCUT_CUDA_CHECK_LAUNCH();
  cell_keys_kernel<Real><<<blocks, 256, 0, stream>>>(in, lattices, extents, keys, index);
  RAYCUT_CUDA_CHECK_LAUNCH();
  RAYCUT_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(sort_storage, sort_bytes, keys, sorted_keys,
                                                    index, sorted, static_cast<std::int64_t>(n), 0,
                                                    key_bits, stream));
  cell_starts_kernel<Real><<<static_cast<unsigned>((n + 1 + 255) / 256), 256, 0, stream>>>(
      in, sorted_keys, sorted, starts, static_cast<Real*>(sorted_xyz));
  RAYCUT_CUDA_CHECK_LAUNCH();
}

}  // namespace

void list_pairs_small_systems(const Context& ctx, const DeviceSystems& systems, double cutoff,
                              const PairOptions& options, const StaticPairs& out) {
  const Input in = make_input(systems, cutoff, options, out);
  const std::size_t n = systems.size;
  const bool wide = systems.scalar == Scalar::float64;
  const bool by_cells = in.by_cells && n > 0;

  const auto stream = static_cast<cudaStream_t>(ctx.stream);
  // Temporaries in one block: per-row counts (or list_rows's words, and its ticket counter past
  // them), the status word, the systems' extents and the offsets (zeroed together), the
  // lattices, the cells' arrays, and the scan's and the sort's storage.
  std::size_t scan_bytes = 0, sort_bytes = 0;
  int key_bits = 1;
  while (key_bits < 32 && (std::uint64_t(1) << key_bits) < n) ++key_bits;
  if (by_cells) {
    RAYCUT_CUDA_CHECK(cub::DeviceScan::ExclusiveSum(
        nullptr, scan_bytes, static_cast<unsigned long long*>(nullptr),
        static_cast<unsigned long long*>(nullptr), static_cast<std::int64_t>(n + 1), stream));
    RAYCUT_CUDA_CHECK(cub::DeviceRadixSort::SortPairs(
        nullptr, sort_bytes, static_cast<std::uint32_t*>(nullptr),
        static_cast<std::uint32_t*>(nullptr), static_cast<std::uint32_t*>(nullptr),
        static_cast<std::uint32_t*>(nullptr), static_cast<std::int64_t>(n), 0, key_bits, stream));
  }
  const std::size_t counts_bytes = align_up((n + 1) * sizeof(unsigned long long) + sizeof(int));
  const std::size_t extents_bytes =
      by_cells ? align_up(extent_words * n * sizeof(unsigned long long)) : 0;
  const std::size_t offsets_bytes = align_up((n + 1) * sizeof(unsigned long long));
  const auto lattices_wanted = static_cast<std::size_t>(lattice_count(in));
  const std::size_t lattices_bytes = align_up(lattices_wanted * sizeof(Lattice));
  const std::size_t slots_bytes = by_cells ? align_up(n * sizeof(std::uint32_t)) : 0;
  const std::size_t starts_bytes = by_cells ? align_up((n + 1) * sizeof(std::uint32_t)) : 0;
  const std::size_t sorted_xyz_bytes =
      by_cells ? align_up(3 * n * (wide ? sizeof(double) : sizeof(float))) : 0;
  const std::size_t bytes = counts_bytes + extents_bytes + offsets_bytes + lattices_bytes +
                            4 * slots_bytes + starts_bytes + sorted_xyz_bytes +
                            align_up(scan_bytes) + align_up(sort_bytes);
  char* block = static_cast<char*>(allocate(ctx, bytes));
  char* at = block;
  const auto take = [&](std::size_t size) {
    char* p = at;
    at += size;
    return p;
  };
  auto* counts = reinterpret_cast<unsigned long long*>(take(counts_bytes));
  auto* status = reinterpret_cast<int*>(counts + n + 1);
  auto* extents = reinterpret_cast<unsigned long long*>(take(extents_bytes));
  auto* offsets = reinterpret_cast<unsigned long long*>(take(offsets_bytes));
  auto* lattices = reinterpret_cast<Lattice*>(take(lattices_bytes));
  auto* keys = reinterpret_cast<std::uint32_t*>(take(slots_bytes));
  auto* sorted_keys = reinterpret_cast<std::uint32_t*>(take(slots_bytes));
  auto* index = reinterpret_cast<std::uint32_t*>(take(slots_bytes));
  auto* sorted = reinterpret_cast<std::uint32_t*>(take(slots_bytes));
  auto* starts = reinterpret_cast<std::uint32_t*>(take(starts_bytes));
  void* sorted_xyz = take(sorted_xyz_bytes);
  void* scan_storage = take(align_up(scan_bytes));
  void* sort_storage = take(align_up(sort_bytes));
  try {
    // counts, status, extents and offsets: zeroed together, by the lattices' launch if any
    const std::size_t zeroed_bytes = counts_bytes + extents_bytes + offsets_bytes;
    if (n > 0 && lattices_wanted > 0) {
      const std::size_t words = zeroed_bytes / sizeof(unsigned long long);
      const std::size_t blocks =
          std::max((lattices_wanted + 63) / 64, std::min<std::size_t>((words + 63) / 64, 1024));
      const auto lattice = wide ? lattices_kernel<double> : lattices_kernel<float>;
      lattice<<<static_cast<unsigned>(blocks), 64, 0, stream>>>(
          in, lattices, static_cast<std::int64_t>(lattices_wanted), counts, words);
      RAYCUT_CUDA_CHECK_LAUNCH();
    } else {
      RAYCUT_CUDA_CHECK(cudaMemsetAsync(counts, 0, zeroed_bytes, stream));
    }
    const CellTable cells{extents, sorted, starts, sorted_xyz};
    if (by_cells) {
      const auto make = wide ? make_cells<double> : make_cells<float>;
      make(in, lattices, extents, keys, sorted_keys, index, sorted, starts, sorted_xyz,
           sort_storage, sort_bytes, key_bits, stream);
    }
    const auto rows = wide ? (by_cells ? row_passes<double, true> : row_passes<double, false>)
                           : (by_cells ? row_passes<float, true> : row_passes<float, false>);
    rows(in, lattices, cells, counts, status, offsets, scan_storage, scan_bytes, out, stream);
    const std::size_t entries = out.capacity * std::max<std::size_t>(out.systems, 1);
    const std::size_t pad_blocks =
        std::min<std::size_t>((std::max(entries, out.systems) + 255) / 256 + 1, 1024);
    if (out.systems)
      finish_systems<<<static_cast<unsigned>(pad_blocks), 256, 0, stream>>>(in, offsets, status,
                                                                            out);
    else
      finish<<<static_cast<unsigned>(pad_blocks), 256, 0, stream>>>(offsets + n, status, in.run_if,
                                                                    out);
    RAYCUT_CUDA_CHECK_LAUNCH();
  } catch (...) {
    deallocate(ctx, block, bytes);
    throw;
  }
  deallocate(ctx, block, bytes);
}

std::int64_t read_pair_count(const Context& ctx, const std::int64_t* device_count) {
  std::int64_t count = 0;
  const auto stream = static_cast<cudaStream_t>(ctx.stream);
  RAYCUT_CUDA_CHECK(
      cudaMemcpyAsync(&count, device_count, sizeof count, cudaMemcpyDeviceToHost, stream));
  RAYCUT_CUDA_CHECK(cudaStreamSynchronize(stream));
  switch (count) {
    case count_non_finite_position:
      throw Error(ErrorCode::invalid_input, "a position is NaN or infinite");
    case count_unsorted_batch:
      throw Error(ErrorCode::invalid_input,
                  "batch is not sorted: the particles of each system must be contiguous");
    case count_invalid_cell:
      throw Error(ErrorCode::invalid_input,
                  "a cell has non-finite entries or linearly dependent periodic rows");
    case count_batch_out_of_range:
      throw Error(ErrorCode::invalid_input,
                  "a batch value is negative or has no cell or pbc row (one per system)");
    case count_too_many_images:
      throw Error(ErrorCode::invalid_input,
                  "a periodic cell is so much thinner than the cutoff that a pair has over 2^24 "
                  "images (use the Engine's cell list for such boxes)");
    default:
      if (count < 0)
        throw Error(ErrorCode::internal, "unknown pair count code " + std::to_string(count));
      return count;
  }
}

namespace {
// The block's layout: i, j, S and count, each 256-byte aligned.
struct PairLayout {
  std::size_t i = 0, j = 0, shifts = 0, count = 0, bytes = 0;
  explicit PairLayout(std::size_t capacity) {
    if (capacity > max_capacity)  // the sizes below would wrap around
      throw Error(
          ErrorCode::invalid_argument,
          "StaticPairBuffer: capacity " + std::to_string(capacity) + " is above the largest, 2^56");
    j = align_up(capacity * sizeof(std::int64_t));
    shifts = j + align_up(capacity * sizeof(std::int64_t));
    count = shifts + align_up(3 * capacity * sizeof(std::int32_t));
    bytes = count + align_up(sizeof(std::int64_t));
  }
};
}  // namespace

StaticPairBuffer::StaticPairBuffer(std::size_t capacity, const Context& ctx)
    : bytes_(PairLayout(capacity).bytes), capacity_(capacity), ctx_(ctx) {
  block_ = allocate(ctx_, bytes_);
}

StaticPairBuffer::~StaticPairBuffer() {
  release();
}

StaticPairBuffer::StaticPairBuffer(StaticPairBuffer&& o) noexcept
    : block_(std::exchange(o.block_, nullptr)),
      bytes_(std::exchange(o.bytes_, 0)),
      capacity_(std::exchange(o.capacity_, 0)),
      ctx_(o.ctx_) {}

StaticPairBuffer& StaticPairBuffer::operator=(StaticPairBuffer&& o) noexcept {
  if (this != &o) {
    release();
    block_ = std::exchange(o.block_, nullptr);
    bytes_ = std::exchange(o.bytes_, 0);
    capacity_ = std::exchange(o.capacity_, 0);
    ctx_ = o.ctx_;
  }
  return *this;
}

void StaticPairBuffer::release() noexcept {
  deallocate(ctx_, block_, bytes_);
  block_ = nullptr;
}

std::int64_t* StaticPairBuffer::i() const {
  return reinterpret_cast<std::int64_t*>(static_cast<char*>(block_) + PairLayout(capacity_).i);
}
std::int64_t* StaticPairBuffer::j() const {
  return reinterpret_cast<std::int64_t*>(static_cast<char*>(block_) + PairLayout(capacity_).j);
}
std::int32_t* StaticPairBuffer::shifts() const {
  return reinterpret_cast<std::int32_t*>(static_cast<char*>(block_) + PairLayout(capacity_).shifts);
}
std::int64_t* StaticPairBuffer::count() const {
  return reinterpret_cast<std::int64_t*>(static_cast<char*>(block_) + PairLayout(capacity_).count);
}

StaticPairs StaticPairBuffer::view(std::int64_t pad_index) const {
  if (!block_) throw Error(ErrorCode::invalid_argument, "StaticPairBuffer: no buffer (moved from)");
  return StaticPairs{i(), j(), shifts(), count(), capacity_, pad_index};
}

std::int64_t list_pairs_small_systems_growing(const Context& ctx, const DeviceSystems& systems,
                                              double cutoff, const PairOptions& options,
                                              StaticPairBuffer& buffer) {
  const auto pad = static_cast<std::int64_t>(systems.size);
  if (!buffer.allocated()) buffer = StaticPairBuffer(0, ctx);
  list_pairs_small_systems(ctx, systems, cutoff, options, buffer.view(pad));
  std::int64_t count = read_pair_count(ctx, buffer.count());
  if (static_cast<std::size_t>(count) > buffer.capacity()) {
    buffer = StaticPairBuffer(static_cast<std::size_t>(count + count / 8), ctx);
    list_pairs_small_systems(ctx, systems, cutoff, options, buffer.view(pad));
    count = read_pair_count(ctx, buffer.count());
  }
  return count;
}

namespace {

__global__ void set_flag(int* flag, int value) {
  *flag = value;
}

// flag = 1 when some particle is more than `limit` from its reference place (double distances).
template <class Real>
__global__ void mark_moved(const Real* now, const Real* then, std::int64_t n, double limit2,
                           int* flag) {
  for (std::int64_t i = std::int64_t(blockIdx.x) * blockDim.x + threadIdx.x; i < n;
       i += std::int64_t(gridDim.x) * blockDim.x) {
    double d2 = 0;
    for (int k = 0; k < 3; ++k) {
      const double d = double(now[3 * i + k]) - double(then[3 * i + k]);
      d2 += d * d;
    }
    if (!(d2 <= limit2)) *flag = 1;  // racing writes of the same value; NaN counts as moved
  }
}

// reference = now where the flag is set (after a rebuild).
__global__ void copy_if_flag(const int* flag, const unsigned* now, unsigned* reference,
                             std::size_t words) {
  if (*flag == 0) return;
  for (std::size_t w = std::size_t(blockIdx.x) * blockDim.x + threadIdx.x; w < words;
       w += std::size_t(gridDim.x) * blockDim.x)
    reference[w] = now[w];
}

unsigned grid_for(std::size_t items) {
  return static_cast<unsigned>(
      std::max<std::size_t>(std::min<std::size_t>((items + 255) / 256, 1024), 1));
}

}  // namespace

DeviceVerletList::DeviceVerletList(const Context& ctx, double cutoff, double skin,
                                   std::size_t capacity, const PairOptions& options)
    : ctx_(ctx), cutoff_(cutoff), skin_(skin), options_(options) {
  detail::validate_cutoff_value(cutoff);
  if (!(skin >= 0) || !std::isfinite(cutoff + skin))
    throw Error(ErrorCode::invalid_argument,
                "DeviceVerletList: skin must be finite and >= 0, got " + std::to_string(skin));
  pairs_ = StaticPairBuffer(capacity, ctx_);
  flag_ = static_cast<int*>(allocate(ctx_, sizeof(int)));
}

DeviceVerletList::~DeviceVerletList() {
  deallocate(ctx_, reference_, reference_bytes_);
  deallocate(ctx_, flag_, sizeof(int));
}

void DeviceVerletList::reserve(std::size_t capacity) {
  if (capacity <= pairs_.capacity()) return;
  RAYCUT_CUDA_CHECK(cudaStreamSynchronize(static_cast<cudaStream_t>(ctx_.stream)));
  pairs_ = StaticPairBuffer(capacity, ctx_);
  first_ = true;
}

void DeviceVerletList::update(const DeviceSystems& systems) {
  const auto stream = static_cast<cudaStream_t>(ctx_.stream);
  const std::size_t element = systems.scalar == Scalar::float64 ? sizeof(double) : sizeof(float);
  const std::size_t bytes = 3 * systems.size * element;
  if (!first_ && (systems.size != size_ || systems.scalar != scalar_))
    throw Error(ErrorCode::invalid_argument,
                "DeviceVerletList::update: " + std::to_string(systems.size) +
                    " particles, but the list was built over " + std::to_string(size_) +
                    " (of the same type): make a new list for a new system");
  if (first_) {
    deallocate(ctx_, reference_, reference_bytes_);
    reference_ = nullptr;
    reference_bytes_ = bytes ? bytes : 4;  // what deallocate() is told: the size allocated
    reference_ = allocate(ctx_, reference_bytes_);
    size_ = systems.size;
    scalar_ = systems.scalar;
    set_flag<<<1, 1, 0, stream>>>(flag_, 1);
  } else {
    set_flag<<<1, 1, 0, stream>>>(flag_, 0);
    const double limit = skin_ / 2;
    const auto n = static_cast<std::int64_t>(size_);
    if (n > 0) {
      if (scalar_ == Scalar::float64)
        mark_moved<<<grid_for(size_), 256, 0, stream>>>(
            static_cast<const double*>(systems.positions), static_cast<const double*>(reference_),
            n, limit * limit, flag_);
      else
        mark_moved<<<grid_for(size_), 256, 0, stream>>>(
            static_cast<const float*>(systems.positions), static_cast<const float*>(reference_), n,
            limit * limit, flag_);
    }
  }
  RAYCUT_CUDA_CHECK_LAUNCH();
  PairOptions options = options_;
  options.run_if = flag_;
  list_pairs_small_systems(ctx_, systems, cutoff_ + skin_, options,
                           pairs_.view(static_cast<std::int64_t>(size_)));
  if (bytes > 0) {
    copy_if_flag<<<grid_for(bytes / 4), 256, 0, stream>>>(
        flag_, static_cast<const unsigned*>(systems.positions), static_cast<unsigned*>(reference_),
        bytes / 4);
    RAYCUT_CUDA_CHECK_LAUNCH();
  }
  first_ = false;
}

namespace detail {
void list_pairs_small_systems_on_host(const DeviceSystems& systems, double cutoff,
                                      const PairOptions& options, const StaticPairs& out) {
  const Input in = make_input(systems, cutoff, options, out);
  if (systems.scalar == Scalar::float64)
    host_pass<double>(in, out);
  else
    host_pass<float>(in, out);
}
}  // namespace detail

}  // namespace raycut
