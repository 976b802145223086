// Neighbour lists as functors of the one pair pass (host and device): a count pass, a fill pass
// at offsets from the scan of the counts, and the padded matrix in one pass. Every method builds
// its lists with these.
#pragma once

#include <cmath>
#include <cstdint>

#include "raycut/kernels.hpp"
#include "raycut/predicate.hpp"

namespace raycut::detail {

// Half lists keep, of (i, j, S) and (j, i, -S), the one with i < j, or i == j and S
// lexicographically positive (a self-image; (i, i, 0) never reaches a functor).
struct HalfFilter {
  using options = functor_options<option::accepts>;
  bool half;
  RAYCUT_HD bool accepts(std::uint32_t i, std::uint32_t j, const Shift& s) const {
    return !half || i < j || (i == j && s.positive());
  }
};

// The full list's count reads no source (no lookup with images); the half list's filters.
struct ListCount {
  using Accumulator = std::uint32_t;
  using options = functor_options<option::combine>;
  std::uint32_t* counts;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, Vec3, float) const { ++acc; }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const { counts[i] = acc; }
};

struct HalfListCount : HalfFilter {
  using Accumulator = std::uint32_t;
  using options = functor_options<option::accepts, option::combine>;
  std::uint32_t* counts;
  RAYCUT_HD void operator()(Accumulator& acc, std::uint32_t, std::uint32_t, Vec3, float,
                            const Shift&) const {
    ++acc;
  }
  RAYCUT_HD static void combine(Accumulator& a, const Accumulator& b) { a += b; }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& acc) const { counts[i] = acc; }
};

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
struct ListFill : HalfFilter {
  using Accumulator = std::uint64_t;  // the next entry of the row
  using options = functor_options<option::accepts, option::init, option::emits_entries>;
  const std::uint64_t* offsets;
  std::uint32_t* indices;
  float* distances;
  float* vectors;
  std::int32_t* shifts;
  std::int64_t* rows;  // COO (ListOptions::coo): i and j as int64, in place of `indices`
  std::int64_t* columns;
  RAYCUT_HD Accumulator init(std::uint32_t i) const { return offsets[i]; }
  RAYCUT_HD void operator()(Accumulator& slot, std::uint32_t i, std::uint32_t j, Vec3 r, float r2,
                            const Shift& s) const {
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

// What a padded pass reports, in the method's memory: rows over K, the largest count.
struct PaddedOverflow {
  unsigned long long rows;
  std::uint32_t largest;
};

// Row i of the [N, K] matrix: its first K neighbours, then `n` (an invalid index) to the end;
// counts[i] the true count, and the overflow recorded, never hidden.
struct PaddedFill : HalfFilter {
  using Accumulator = std::uint32_t;  // the row's next entry (its count so far)
  using options = functor_options<option::accepts, option::emits_entries>;
  std::uint32_t k;
  std::uint32_t n;
  std::uint32_t* indices;
  std::uint32_t* counts;
  std::int32_t* shifts;  // 3 per entry, or null; padding entries get S = 0
  PaddedOverflow* overflow;
  RAYCUT_HD void operator()(Accumulator& count, std::uint32_t i, std::uint32_t j, Vec3, float,
                            const Shift& s) const {
    if (count < k) {
      const std::uint64_t e = std::uint64_t{i} * k + count;
      indices[e] = j;
      if (shifts) {
        shifts[3 * e] = s.a;
        shifts[3 * e + 1] = s.b;
        shifts[3 * e + 2] = s.c;
      }
    }
    ++count;
  }
  RAYCUT_HD void finish(std::uint32_t i, Accumulator& count) const {
    counts[i] = count;
    for (std::uint32_t c = count; c < k; ++c) {
      const std::uint64_t e = std::uint64_t{i} * k + c;
      indices[e] = n;
      if (shifts) shifts[3 * e] = shifts[3 * e + 1] = shifts[3 * e + 2] = 0;
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

}  // namespace raycut::detail
