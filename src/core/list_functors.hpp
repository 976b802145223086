// Neighbour lists as functors of the one pair pass (host and device): a count pass, a fill pass
// at offsets from the scan of the counts, and the padded matrix in one pass. Every method builds
// its lists with these.
#pragma once

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "raycut/detail/images.hpp"
#include "raycut/kernels.hpp"
#include "raycut/predicate.hpp"

namespace raycut::detail {

// Per-pair cutoffs (ListOptions::cutoffs) in the method's memory space: pair (i, j, S) is kept
// iff |r| < c_ij. The pass's float r2 decides where it is certainly on one side of c_ij^2; the
// band where its rounding could matter is decided in double from the caller's positions
// (ExactImages, where the pass has them: host points with images), so a pair is the float64
// answer and (i, j, S), (j, i, -S) are decided alike. Without ExactImages, r is the difference
// of the float positions themselves, exactly antisymmetric, and is compared with c_ij in double.
struct PairCutoffFilter {
  const double* radius = nullptr;          // by particle: c_ij = r_i + r_j
  const std::uint32_t* species = nullptr;  // by particle, with `table`
  const double* table = nullptr;           // kinds x kinds: c_ij = table[s_i * kinds + s_j]
  std::uint32_t kinds = 0;
  ExactImages exact;  // exact.image null: none
  RAYCUT_HD bool active() const { return radius != nullptr || table != nullptr; }
  RAYCUT_HD double cutoff(std::uint32_t i, std::uint32_t j) const {
    return radius ? radius[i] + radius[j] : table[species[i] * kinds + species[j]];
  }
  RAYCUT_HD bool keeps(std::uint32_t i, std::uint32_t j, const Shift& s, float r2) const {
    if (!active()) return true;
    const double c = cutoff(i, j), c2 = c * c;
    if (!exact.image) return static_cast<double>(r2) < c2;
    const double slack = float_band_slack(c, exact.rounding);
    if (r2 < c2 - slack) return true;
    if (r2 >= c2 + slack) return false;
    const double shift[3] = {static_cast<double>(s.a), static_cast<double>(s.b),
                             static_cast<double>(s.c)};
    double r[3];
    return exact_pair_vector(exact, i, j, shift, r) < c2;
  }
};

// What a list keeps of the pairs the pass offers. Half lists keep, of (i, j, S) and
// (j, i, -S), the one with i < j, or i == j and S lexicographically positive (a self-image;
// (i, i, 0) never reaches a functor); per-pair cutoffs keep the pairs within their own.
// any_row (ListOptions::any_row): a traversal with a half stencil (the CUDA grid's, the CPU cell
// list's) may keep the pair in the row of whichever particle it meets it from; it then decides
// the pairs of two home particles itself and hands the functor a copy with half off
// (for_candidate, detail/images.hpp).
struct ListFilter {
  using options = functor_options<option::accepts, option::repeatable>;
  bool half = false;
  PairCutoffFilter cutoffs;
  bool any_row = false;
  RAYCUT_HD bool accepts(std::uint32_t i, std::uint32_t j, const Shift& s) const {
    return !half || half_keeps(i, j, s);
  }
  // The CPU loop drops sources below it before the predicate (pairs.hpp): a half list's row i
  // has none (2026-12-05, the 200,000-particle LJ liquid, one thread: see docs/pair-pass.md).
  std::uint32_t lowest_source(std::uint32_t i) const { return half ? i : 0; }
  RAYCUT_HD bool within(std::uint32_t i, std::uint32_t j, const Shift& s, float r2) const {
    return cutoffs.keeps(i, j, s, r2);
  }
  // Whether the count must read j and S (else ListCount, the open traversal's count).
  bool filters() const { return half || cutoffs.active(); }
};

// The full list's count reads no source (no lookup with images); a filtered list's reads them.
struct ListCount {
  using Accumulator = std::uint32_t;
  using options = functor_options<option::combine, option::repeatable>;
  std::uint32_t* counts;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, Vec3, float) const { ++acc; }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const { counts[i] = acc; }
};

struct FilteredListCount : ListFilter {
  using Accumulator = std::uint32_t;
  using options = functor_options<option::accepts, option::combine, option::repeatable>;
  std::uint32_t* counts;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t i, std::uint32_t j, Vec3, float r2,
                            const Shift& s) const {
    if (within(i, j, s, r2)) ++acc;
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const { counts[i] = acc; }
};

// A list's count pass: ListCount, or FilteredListCount where the list filters pairs.
template <class Run>
void count_list(const ListFilter& filter, std::uint32_t* counts, Run&& run) {
  if (filter.filters())
    run(FilteredListCount{filter, counts});
  else
    run(ListCount{counts});
}

// |r| in float, equal to the length of the vector r itself to float precision: sqrtf of the
// predicate's r2 where r2 is far from underflow (the usual case, no extra work), else from r
// scaled by a power of two (exact) so that its squares are normal floats. Without the scaling a
// pair 1e-22 apart had d off by 1% (r2 ~1e-44 is a subnormal float) while D was right.
RAYCUT_HD float pair_distance(Vec3 r, float r2) {
  if (r2 >= 0x1p-100f) return sqrtf(r2);
  const float largest = fmaxf(fabsf(r.x), fmaxf(fabsf(r.y), fabsf(r.z)));
  if (largest == 0.0f) return 0.0f;
  const int e = ilogbf(largest);
  const float x = ldexpf(r.x, -e), y = ldexpf(r.y, -e), z = ldexpf(r.z, -e);
  return ldexpf(sqrtf(fmaf(z, z, fmaf(y, y, x * x))), e);
}

// Row i written from offsets[i]; distances, vectors and shifts where asked (null otherwise).
struct ListFill : ListFilter {
  using Accumulator = std::uint64_t;  // the next entry of the row
  using options =
      functor_options<option::accepts, option::init, option::emits_entries, option::repeatable>;
  const std::uint64_t* offsets;
  std::uint32_t* indices;
  float* distances;
  float* vectors;
  std::int32_t* shifts;
  std::int64_t* rows;  // COO (ListOptions::coo): i and j as int64, in place of `indices`
  std::int64_t* columns;
  // Entries at or past it are counted, not written (a static-capacity list: StaticPairs).
  std::uint64_t capacity = ~std::uint64_t{0};
  RAYCUT_HD Accumulator init(std::uint32_t i) const { return offsets[i]; }
  RAYCUT_HD void operator()(Accumulator& slot, std::uint32_t i, std::uint32_t j, Vec3 r, float r2,
                            const Shift& s) const {
    if (within(i, j, s, r2)) write(slot, i, j, r, r2, s);
  }
  // The entry at `slot`, the pair already kept.
  RAYCUT_HD void write(Accumulator& slot, std::uint32_t i, std::uint32_t j, Vec3 r, float r2,
                       const Shift& s) const {
    if (slot >= capacity) {
      ++slot;
      return;
    }
    if (columns) {
      rows[slot] = i;
      columns[slot] = j;
    } else {
      indices[slot] = j;
    }
    if (shifts) {
      shifts[3 * slot] = s.a;
      shifts[3 * slot + 1] = s.b;
      shifts[3 * slot + 2] = s.c;
    }
    if (distances) distances[slot] = pair_distance(r, r2);
    if (vectors) {
      vectors[3 * slot] = r.x;
      vectors[3 * slot + 1] = r.y;
      vectors[3 * slot + 2] = r.z;
    }
    ++slot;
  }
  RAYCUT_HD void finish(std::uint32_t, Accumulator&) const {}
};

// The count and the fill of a list without per-pair cutoffs, for a GPU traversal: within() is
// constant, so PairCutoffFilter's double arithmetic is not compiled into the kernel, where it
// would set the register count of every list (64 against 40 for the grid's fill: docs/grid.md,
// "Registers"). Made from the general functor when its cutoffs are inactive.
struct PlainFilteredListCount : FilteredListCount {
  RAYCUT_HD bool within(std::uint32_t, std::uint32_t, const Shift&, float) const { return true; }
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, std::uint32_t, Vec3, float,
                            const Shift&) const {
    ++acc;
  }
};
struct PlainListFill : ListFill {
  RAYCUT_HD bool within(std::uint32_t, std::uint32_t, const Shift&, float) const { return true; }
  RAYCUT_HD void operator()(Accumulator& slot, std::uint32_t i, std::uint32_t j, Vec3 r, float r2,
                            const Shift& s) const {
    write(slot, i, j, r, r2, s);
  }
};

// The fill of the common list, j (and S with Shifts) into a list of unbounded capacity: its write
// tests nothing at run time, where ListFill's tests each output and the capacity for every pair
// written (the fill is issue-bound: docs/benchmarks.md, "The half stencil, and the roofline").
template <bool Shifts>
struct IndexFill : PlainListFill {
  RAYCUT_HD void operator()(Accumulator& slot, std::uint32_t, std::uint32_t j, Vec3, float,
                            const Shift& s) const {
    indices[slot] = j;
    if constexpr (Shifts) {
      shifts[3 * slot] = s.a;
      shifts[3 * slot + 1] = s.b;
      shifts[3 * slot + 2] = s.c;
    }
    ++slot;
  }
};

// What a padded pass reports, in the method's memory: rows over K, the largest count.
struct PaddedOverflow {
  unsigned long long rows;
  std::uint32_t largest;
};

// Row i of the [N, K] matrix: its first K neighbours, then `n` (an invalid index) to the end;
// counts[i] the true count, and the overflow recorded, never hidden.
struct PaddedFill : ListFilter {
  using Accumulator = std::uint32_t;  // the row's next entry (its count so far)
  using options = functor_options<option::accepts, option::emits_entries, option::repeatable>;
  std::uint32_t k;
  std::uint32_t n;
  std::uint32_t* indices;
  std::uint32_t* counts;
  std::int32_t* shifts;  // 3 per entry, or null; padding entries get S = 0
  PaddedOverflow* overflow;
  RAYCUT_HD void operator()(Accumulator& count, std::uint32_t i, std::uint32_t j, Vec3, float r2,
                            const Shift& s) const {
    if (!within(i, j, s, r2)) return;
    if (shifts)
      write<true>(count, i, j, s);
    else
      write<false>(count, i, j, s);
  }
  // The row's next entry, the pair already kept; S written when Shifts (then `shifts` is set).
  template <bool Shifts>
  RAYCUT_HD void write(Accumulator& count, std::uint32_t i, std::uint32_t j, const Shift& s) const {
    if (count < k) {
      const std::uint64_t e = std::uint64_t{i} * k + count;
      indices[e] = j;
      if constexpr (Shifts) {
        shifts[3 * e] = s.a;
        shifts[3 * e + 1] = s.b;
        shifts[3 * e + 2] = s.c;
      }
    }
    ++count;
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& count) const {
    if (shifts)
      finish<true>(i, count);
    else
      finish<false>(i, count);
  }
  // The row's count, its padding (S = 0 when Shifts) and the overflow.
  template <bool Shifts>
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& count) const {
    counts[i] = count;
    for (std::uint32_t c = count; c < k; ++c) {
      const std::uint64_t e = std::uint64_t{i} * k + c;
      indices[e] = n;
      if constexpr (Shifts) shifts[3 * e] = shifts[3 * e + 1] = shifts[3 * e + 2] = 0;
    }
    if (count > k) {
#if defined(__CUDA_ARCH__)
      atomicAdd(&overflow->rows, 1ull);
      atomicMax(&overflow->largest, count);
#else
      __atomic_fetch_add(&overflow->rows, 1ull, __ATOMIC_RELAXED);
      std::uint32_t seen = __atomic_load_n(&overflow->largest, __ATOMIC_RELAXED);
      while (seen < count && !__atomic_compare_exchange_n(&overflow->largest, &seen, count, true,
                                                          __ATOMIC_RELAXED, __ATOMIC_RELAXED)) {
      }
#endif
    }
  }
};

// The padded fill without per-pair cutoffs, for a GPU traversal (as PlainListFill and
// IndexFill): within() constant, and S written or not as the type says, so that neither
// PairCutoffFilter's double arithmetic nor a test of `shifts` is in the pair's loop. With both
// in, the grid's padded matrix took 1.42x the time of the revision before per-pair cutoffs (H200,
// uniform beta 32 p 32: docs/benchmarks.md, "The padded fill without idle cutoffs").
template <bool Shifts>
struct PlainPaddedFill : PaddedFill {
  RAYCUT_HD bool within(std::uint32_t, std::uint32_t, const Shift&, float) const { return true; }
  RAYCUT_HD void operator()(Accumulator& count, std::uint32_t i, std::uint32_t j, Vec3, float,
                            const Shift& s) const {
    write<Shifts>(count, i, j, s);
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& count) const {
    PaddedFill::finish<Shifts>(i, count);
  }
};

// Runs run(f), or run(f) as its Plain functor above where f has no per-pair cutoffs (and as an
// IndexFill where a list asks for no more than j and S). GPU traversals run their functors so.
template <class F, class Run>
void run_without_idle_cutoffs(const F& f, Run&& run) {
  if constexpr (std::is_same_v<F, ListFill>) {
    if (!f.cutoffs.active() && !f.columns && !f.distances && !f.vectors &&
        f.capacity == ~std::uint64_t{0}) {
      if (f.shifts) return run(IndexFill<true>{PlainListFill{f}});
      return run(IndexFill<false>{PlainListFill{f}});
    }
    if (!f.cutoffs.active()) return run(PlainListFill{f});
  } else if constexpr (std::is_same_v<F, FilteredListCount>) {
    if (!f.cutoffs.active()) return run(PlainFilteredListCount{f});
  } else if constexpr (std::is_same_v<F, PaddedFill>) {
    if (!f.cutoffs.active()) {
      if (f.shifts) return run(PlainPaddedFill<true>{f});
      return run(PlainPaddedFill<false>{f});
    }
  }
  run(f);
}

// One of a row's K nearest (PaddedOptions::nearest), in the order of raycut.torch.knn: |r|^2,
// then j, then S.
struct NearestEntry {
  double r2;
  std::uint32_t j;
  std::int32_t s[3];
  bool operator<(const NearestEntry& o) const {
    if (r2 != o.r2) return r2 < o.r2;
    if (j != o.j) return j < o.j;
    for (int a = 0; a < 3; ++a)
      if (s[a] != o.s[a]) return s[a] < o.s[a];
    return false;
  }
};

// The padded matrix of each row's K nearest, nearest first (CPU methods). A row's pairs are
// collected in a buffer of at least 2K; a full buffer keeps its K nearest (nth_element), whose
// farthest then bounds the row: a pair not nearer is dropped at once. The row's K nearest are
// selected and sorted when it finishes. Selection in bulk beats a max-heap fed pair by pair
// (2026-12-05, 100,000 uniform points, K = 17 and 65 at radii holding 26 and 85 on average, one
// thread: 161 -> 147 ms and 512-525 -> 408-409 ms). The buffer is scratch of the thread visiting
// the row (a CPU pass visits one target at a time per thread), so it stays in cache. Counts and
// overflow as PaddedFill's (a row over K is expected here, and still reported). |r|^2 is exact for
// the positions the engine holds: the double vector of ExactImages where the points have images
// (float64 sources when built from them), else the float positions' differences, which double
// holds exactly. Host only: the GPU passes share a row between lanes.
struct PaddedNearestFill : PaddedFill {
  struct Accumulator {
    std::uint32_t count;  // the row's pairs so far
    std::uint32_t size;   // entries in the buffer
    bool bounded;         // the buffer was cut to K: row[K - 1] is the farthest kept
    NearestEntry* row;    // the buffer, capacity() entries
  };
  using options = functor_options<option::accepts, option::init,
                                  option::repeatable>;  // entries written at finish
  const float* xyz;                                     // the points, without images
  ExactImages exact;                                    // with images (exact.image set)
  std::uint32_t capacity() const { return 2 * k + 64; }
  Accumulator init(std::uint32_t) const {
    thread_local std::vector<NearestEntry> scratch;
    if (scratch.size() < capacity()) scratch.resize(capacity());
    return {0, 0, false, scratch.data()};
  }
  void operator()(Accumulator& acc, std::uint32_t i, std::uint32_t j, Vec3, float r2,
                  const Shift& s) const {
    if (!within(i, j, s, r2)) return;
    ++acc.count;
    const NearestEntry e{squared_length(i, j, s), j, {s.a, s.b, s.c}};
    if (acc.bounded && !(e < acc.row[k - 1])) return;
    acc.row[acc.size++] = e;
    if (acc.size == capacity()) keep_nearest(acc);
  }
  // The buffer cut to its K nearest, the farthest of them last.
  void keep_nearest(Accumulator& acc) const {
    NearestEntry* row = acc.row;
    std::nth_element(row, row + (k - 1), row + acc.size);
    std::swap(row[k - 1], *std::max_element(row, row + k));
    acc.size = k;
    acc.bounded = true;
  }
  void finish(std::uint32_t i, Accumulator& acc) const {
    NearestEntry* row = acc.row;
    const std::uint32_t kept = acc.size < k ? acc.size : k;
    if (acc.size > k) std::nth_element(row, row + (k - 1), row + acc.size);
    std::sort(row, row + kept);
    for (std::uint32_t c = 0; c < kept; ++c) {
      const std::uint64_t e = std::uint64_t{i} * k + c;
      indices[e] = row[c].j;
      if (shifts)
        for (int a = 0; a < 3; ++a) shifts[3 * e + a] = row[c].s[a];
    }
    PaddedFill::finish(i, acc.count);  // counts, padding, overflow
  }
  double squared_length(std::uint32_t i, std::uint32_t j, const Shift& s) const {
    if (exact.image) {
      const double shift[3] = {static_cast<double>(s.a), static_cast<double>(s.b),
                               static_cast<double>(s.c)};
      double r[3];
      return exact_pair_vector(exact, i, j, shift, r);
    }
    double r2 = 0;
    for (int a = 0; a < 3; ++a) {
      const double d = static_cast<double>(xyz[3 * std::size_t{j} + a]) -
                       static_cast<double>(xyz[3 * std::size_t{i} + a]);
      r2 += d * d;
    }
    return r2;
  }
};

}  // namespace raycut::detail
