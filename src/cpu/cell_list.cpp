// CPU cell list with memory O(N) whatever the distribution: particles are sorted by cell key and
// only non-empty cells are stored (sorted keys + start offsets), so a far outlier or a sphere
// surface never allocates a dense grid (a counting sort when the cells' box is no bigger than
// the particles, a comparison sort otherwise). Each cell's up-to-27 non-empty neighbours are
// found once, by a cursor per neighbour row, at build time, and kept as the slot ranges the
// pair loop reads (a row of consecutive cells is one range).
//
// Cells are never coarsened: the key of a cell is its three unbounded axis coordinates (see
// CellKey), not a row-major index into a bounded box, so one particle at 1e9 cutoffs does not
// widen the cells of all the others (which made the list O(N^2): counting 100k uniform points
// plus one at 1e9 took 10-17 s instead of 0.01 s).
//
// Query points (targets that are no source) are sorted after every source and are never
// candidates: a query set over sources costs the pairs with sources only, not the query-query
// candidates rejected one by one (the distributed engine's owned rows, raycut.radius), and a cell's
// sources stay next to the next cell's.
#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <compare>
#include <cstdint>
#include <numeric>
#include <string>
#include <vector>

#include "core/images.hpp"
#include "core/method.hpp"
#include "cpu/host_method.hpp"
#include "raycut/detail/host_threads.hpp"

namespace raycut::detail {
namespace {

// One label per axis, from the particle's float coordinate x and the cell width w (C plus a
// relative margin of 1e-4):
// - near: |floor(x / w)| < 2^30: the cell index floor(x / w) computed in double (relative error
//   ~1e-16, far inside the margin, so a pair the float predicate calls in range is at most one
//   cell apart), biased by 2^31 so that labels are unsigned and ordered like the index;
// - far: beyond, where adjacent floats are more than 16 C apart, so a pair in range has exactly
//   equal coordinates on this axis: the label is the float's bit pattern with the top bit set
//   (never equal to a near label), and the cell has no neighbour cells along this axis.
// Every float gets a label (|x / w| <= 2^128 / 2^-60 fits a double), with no box, no clamping and
// no coarsening; keys compare lexicographically (z, y, x), so near cells sort row-major.
// Batches put the system first: systems never share a cell, and a stencil never leaves its
// system.
struct CellKey {
  std::uint64_t system, z, y, x;
  auto operator<=>(const CellKey&) const = default;
};

constexpr double near_limit = 0x1p30;
constexpr std::uint64_t near_bias = std::uint64_t{1} << 31;
constexpr std::uint64_t far_tag = std::uint64_t{1} << 63;

std::uint64_t axis_label(float x, double inverse_width) {
  const double u = std::floor(static_cast<double>(x) * inverse_width);
  if (std::fabs(u) < near_limit)
    return static_cast<std::uint64_t>(static_cast<std::int64_t>(u)) + near_bias;
  return far_tag | std::bit_cast<std::uint32_t>(x);
}

// A particle's place in the sort: (query, cell key, index).
struct Entry {
  std::uint32_t query;  // 1: a query point
  CellKey key;
  std::uint32_t index;
  auto operator<=>(const Entry&) const = default;
};

// Sorts entries (entries[i].index == i) by (query, key, index). When every label is near and
// the box of cells the entries span, (query, system, z, y, x), has at most one cell per entry
// (a liquid, a batch of boxes), by a counting sort over that box: two passes over the entries
// (2026-12-02, the 252,732 points of the 200,000-particle periodic liquid, one thread on a
// shared 2-core machine: 4.5-11 ms, where std::sort of the 40-byte entries took 18-52); else by
// std::sort, as a far outlier or a sparse surface needs. The same order either way: the
// counting sort is stable.
void sort_entries(std::vector<Entry>& entries) {
  const std::size_t n = entries.size();
  if (n < 2) return;
  const auto fields = [](const Entry& e) {
    return std::array<std::uint64_t, 5>{e.query, e.key.system, e.key.z, e.key.y, e.key.x};
  };
  std::array<std::uint64_t, 5> lo, hi;
  lo.fill(~std::uint64_t{0});
  hi.fill(0);
  bool all_near = true;
  for (const Entry& e : entries) {
    const auto f = fields(e);
    for (int k = 0; k < 5; ++k) {
      lo[k] = std::min(lo[k], f[k]);
      hi[k] = std::max(hi[k], f[k]);
    }
    all_near &= !((e.key.z | e.key.y | e.key.x) & far_tag);
  }
  std::uint64_t cells = 1;  // of the box, while at most n
  for (int k = 0; k < 5 && cells <= n; ++k)
    cells = hi[k] - lo[k] >= n ? n + 1 : cells * (hi[k] - lo[k] + 1);
  if (!all_near || cells > n) {
    std::sort(entries.begin(), entries.end());
    return;
  }
  // The entry's cell in the box, row-major in (query, system, z, y, x): the entries' order.
  std::vector<std::uint32_t> cell(n), start(cells + 1, 0);
  for (std::size_t i = 0; i < n; ++i) {
    const auto f = fields(entries[i]);
    std::uint64_t c = 0;
    for (int k = 0; k < 5; ++k) c = c * (hi[k] - lo[k] + 1) + (f[k] - lo[k]);
    cell[i] = static_cast<std::uint32_t>(c);
    ++start[c + 1];
  }
  std::partial_sum(start.begin(), start.end(), start.begin());
  std::vector<Entry> sorted(n);
  for (std::size_t i = 0; i < n; ++i) sorted[start[cell[i]]++] = entries[i];
  entries.swap(sorted);
}

class CellListCpu final : public HostMethod<CellListCpu> {
 public:
  // Candidates of target i: the particles of the non-empty cells around its own, as the slot
  // ranges of its cell (find_neighbour_cells).
  std::size_t candidate_runs(std::size_t i, CandidateRun* out) const {
    const std::uint32_t c = cell_of_particle_[i];
    const std::uint64_t first = run_offsets_[c], runs = run_offsets_[c + 1] - first;
    for (std::uint64_t r = 0; r < runs; ++r) {
      const SlotRange range = runs_[first + r];
      out[r] = {sorted_x_.data() + range.begin,
                sorted_y_.data() + range.begin,
                sorted_z_.data() + range.begin,
                order_.data() + range.begin,
                sorted_source_.data() + range.begin,
                sorted_image_.empty() ? nullptr : sorted_image_.data() + range.begin,
                0,
                range.begin,
                range.end - range.begin};
    }
    return static_cast<std::size_t>(runs);
  }

  // The targets in slot order: consecutive targets then read the same neighbour cells, cached
  // (2026-12-02, lj_forces over the 200,000-particle periodic liquid in random order, one
  // thread on a shared 2-core machine: 372-393 -> 303-316 ms; docs/periodic.md).
  const std::uint32_t* target_order() const { return target_order_.data(); }
  // Their positions in that order: read in sequence, where the caller's order is read at random
  // (2026-12-05, the LJ liquid, one thread: count 10.0-10.3 -> 8.8-9.6 ns per pair, lj_forces
  // 1-3 % less).
  const float* target_order_xyz() const { return target_xyz_.data(); }
  // Each target's slot: the runs' slots are in cell order (the half stencil, HostPass::slots).
  // Only where every candidate point is a target or a target's image: not with query points.
  const std::uint32_t* target_slots() const {
    return targets_are_particles_ ? target_slot_.data() : nullptr;
  }

  void build(const float* xyz, std::size_t n, float cutoff) override {
    build_points(Points::plain(xyz, n), cutoff);
  }

  std::string points_unsupported() const override { return {}; }
  void build_points(const Points& points, float cutoff) override {
    // Particle indices, slots and cell numbers are 32-bit (NeighbourList::indices is uint32).
    const std::size_t n = points.size;
    const float* xyz = points.xyz;
    const std::uint32_t* system = points.systems > 1 ? points.system : nullptr;
    require_indexable(n, "cell-list");
    xyz_.assign(xyz, xyz + 3 * n);
    // Query points are sorted after every source and never offered as candidates (below).
    ImageTables images = points.images;
    targets_are_particles_ =
        images.active() ? images.candidates_are_sources : points.targets == points.size;
    images.candidates_are_sources = true;
    set_positions(xyz_.data(), n, cutoff, points.targets, images);
    // Points rounded at their box's scale: cells as wide as the float distance below which the
    // exact decision is asked, so that they hold every pair it may take (docs/limits.md).
    const double exact_reach = images.exact ? band_reach(*images.exact) : 0;
    inverse_width_ =
        1.0 / std::max(static_cast<double>(cutoff) * (1.0 + width_margin), exact_reach);

    // Sort particles by (query, cell key, index): the sources by cell, then the query points by
    // cell.
    const PointImage* image = points.images.image;  // by point: its source, or a query
    std::vector<Entry> entries(n);
    for_each_index(n, parallel_items, 0, [&](std::size_t i) {
      entries[i] = {
          image && image[i].source == not_a_source ? 1u : 0u,
          {system ? system[i] : 0u, axis_label(xyz[3 * i + 2], inverse_width_),
           axis_label(xyz[3 * i + 1], inverse_width_), axis_label(xyz[3 * i], inverse_width_)},
          static_cast<std::uint32_t>(i)};
    });
    sort_entries(entries);
    order_.resize(n);
    for (std::size_t s = 0; s < n; ++s) order_[s] = entries[s].index;
    // Padded past the last slot: a run reads whole vectors (CandidateRun::padding).
    sorted_x_.assign(n + CandidateRun::padding, 0.0f);
    sorted_y_.assign(n + CandidateRun::padding, 0.0f);
    sorted_z_.assign(n + CandidateRun::padding, 0.0f);
    sorted_source_.assign(n + CandidateRun::padding, not_a_source);
    // With images, their table in slot order too (as the GPU grid keeps it): a list's pass reads
    // each candidate's source and shift in sequence, where the table by point was read at random
    // and its load was a quarter of the fill's samples (2026-12-05, the 100,000-particle
    // periodic liquid, the list with S, one thread, old and new alternated: 163-166 -> 153-163
    // ms).
    sorted_image_.clear();
    if (image) sorted_image_.resize(n);
    for (std::size_t s = 0; s < n; ++s) {
      const float* p = &xyz[3 * std::size_t{order_[s]}];
      sorted_x_[s] = p[0];
      sorted_y_[s] = p[1];
      sorted_z_[s] = p[2];
      sorted_source_[s] = image ? image[order_[s]].source : order_[s];
      if (image) sorted_image_[s] = image[order_[s]];
    }
    target_order_.clear();
    target_xyz_.clear();
    target_slot_.resize(points.targets);
    for (std::size_t s = 0; s < n; ++s)
      if (order_[s] < points.targets) {
        target_slot_[order_[s]] = static_cast<std::uint32_t>(s);
        target_order_.push_back(order_[s]);
        target_xyz_.insert(target_xyz_.end(), {sorted_x_[s], sorted_y_[s], sorted_z_[s]});
      }

    // Compact the non-empty cells: the union of the sources' and the queries' keys, merged; a
    // cell's start indexes the sources (a cell of queries only holds none).
    const std::size_t sources =
        static_cast<std::size_t>(std::partition_point(entries.begin(), entries.end(),
                                                      [](const Entry& e) { return e.query == 0; }) -
                                 entries.begin());
    cell_keys_.clear();
    cell_start_.clear();
    holds_target_.clear();
    cell_of_particle_.resize(n);
    const auto targets = static_cast<std::uint32_t>(points.targets);
    for (std::size_t a = 0, b = sources; a < sources || b < n;) {
      const CellKey k = b == n || (a < sources && entries[a].key < entries[b].key) ? entries[a].key
                                                                                   : entries[b].key;
      const auto c = static_cast<std::uint32_t>(cell_keys_.size());
      cell_keys_.push_back(k);
      cell_start_.push_back(static_cast<std::uint32_t>(a));
      bool target = false;
      for (; a < sources && entries[a].key == k; ++a) {
        cell_of_particle_[order_[a]] = c;
        target |= order_[a] < targets;
      }
      for (; b < n && entries[b].key == k; ++b) {
        cell_of_particle_[order_[b]] = c;
        target |= order_[b] < targets;
      }
      holds_target_.push_back(target);
    }
    cell_start_.push_back(static_cast<std::uint32_t>(sources));
    find_neighbour_cells();
  }

 private:
  std::size_t size() const { return order_.size(); }

  // Each target cell's candidates as slot ranges (runs_), from the non-empty cells within one cell
  // of it (itself included), in key order. A far label has no neighbours along its axis. For each
  // row (dz, dy) around a cell, the first key at or after (system, z + dz, y + dy, x - 1) only
  // moves forward from cell to cell (keys ascend, and adding one offset keeps their order), so a
  // cursor per row finds it in amortised O(1) where a binary search per neighbour cost 15
  // comparisons of 32-byte keys (2026-12-02, the 200,000-particle periodic liquid's cells, one
  // thread: 27-34 -> 3.2-5 ms). Two walks, one to count and one to fill, each over chunks of cells
  // in parallel.
  void find_neighbour_cells() {
    const std::size_t cells = cell_keys_.size();
    std::vector<std::uint32_t> counts(cells);
    walk_neighbour_cells([&](std::size_t c, std::uint32_t) { ++counts[c]; });
    std::vector<std::uint64_t> neighbour_offsets(cells + 1, 0);
    for (std::size_t c = 0; c < cells; ++c)
      neighbour_offsets[c + 1] = neighbour_offsets[c] + counts[c];
    std::vector<std::uint32_t> neighbour_cells(neighbour_offsets[cells]);
    walk_neighbour_cells([&](std::size_t c, std::uint32_t nc) {
      neighbour_cells[neighbour_offsets[c + 1] - counts[c]--] = nc;
    });
    // Cells with consecutive numbers hold consecutive slots: each run of them (a row of up to 3
    // cells) is one range of slots, found here once rather than per target (2026-12-05, 100,000
    // uniform points with 16 neighbours each, the CSR list, one thread: 92 -> 83 ms; the LJ liquid
    // count 10.5 -> 9.9 ns per pair).
    const auto for_each_range = [&](std::size_t c, auto&& f) {
      const std::uint64_t end = neighbour_offsets[c + 1];
      for (std::uint64_t e = neighbour_offsets[c]; e < end;) {
        const std::uint32_t first_cell = neighbour_cells[e];
        std::uint32_t last_cell = first_cell;
        for (++e; e < end && neighbour_cells[e] == last_cell + 1; ++e) ++last_cell;
        f(SlotRange{cell_start_[first_cell], cell_start_[last_cell + 1]});
      }
    };
    run_offsets_.assign(cells + 1, 0);
    for (std::size_t c = 0; c < cells; ++c) {
      std::uint64_t runs = 0;
      for_each_range(c, [&](SlotRange) { ++runs; });
      run_offsets_[c + 1] = run_offsets_[c] + runs;
    }
    runs_.resize(run_offsets_[cells]);
    constexpr std::size_t team_above = 4096;  // cells: below, filling runs costs less than a team
    for_each_index(cells, team_above + 1, 0, [&](std::size_t c) {
      std::uint64_t at = run_offsets_[c];
      for_each_range(c, [&](SlotRange range) { runs_[at++] = range; });
    });
  }

  // emit(c, nc) for every neighbour nc of every cell c holding a target, in ascending nc per cell.
  template <class Emit>
  void walk_neighbour_cells(Emit&& emit) const {
    const std::size_t cells = cell_keys_.size();
    constexpr std::size_t chunk = 4096;
    // Blocks of `chunk` cells, on a team from two blocks.
    for_each_index((cells + chunk - 1) / chunk, 2, 1, [&](std::size_t block) {
      const std::size_t begin = block * chunk;
      std::size_t cursor[3][3];
      bool started[3][3] = {};
      for (std::size_t c = begin; c < std::min(cells, begin + chunk); ++c) {
        if (!holds_target_[c]) continue;  // no target asks for its candidates
        const CellKey k = cell_keys_[c];
        const int rz = (k.z & far_tag) ? 0 : 1, ry = (k.y & far_tag) ? 0 : 1,
                  rx = (k.x & far_tag) ? 0 : 1;
        for (int dz = -rz; dz <= rz; ++dz)
          for (int dy = -ry; dy <= ry; ++dy) {
            const CellKey first{k.system, k.z + dz, k.y + dy, k.x - rx};
            std::size_t& at = cursor[dz + 1][dy + 1];
            if (!started[dz + 1][dy + 1]) {
              at = static_cast<std::size_t>(
                  std::lower_bound(cell_keys_.begin(), cell_keys_.end(), first) -
                  cell_keys_.begin());
              started[dz + 1][dy + 1] = true;
            }
            while (at < cells && cell_keys_[at] < first) ++at;
            for (std::size_t m = at; m < cells; ++m) {
              const CellKey& nk = cell_keys_[m];
              if (nk.system != first.system || nk.z != first.z || nk.y != first.y ||
                  nk.x > k.x + rx)
                break;
              emit(c, static_cast<std::uint32_t>(m));
            }
          }
      }
    });
  }

  std::vector<float> xyz_;
  static constexpr double width_margin = 1e-4;  // as CellGrid: far above predicate round-off
  double inverse_width_ = 1;                    // cells per unit length
  std::vector<std::uint32_t> order_;            // sorted slot -> particle index
  std::vector<std::uint32_t> target_order_;     // the targets (points < targets) in slot order
  bool targets_are_particles_ = true;       // every point a target or an image of one (no queries)
  std::vector<float> target_xyz_;           // their positions, 3 each
  std::vector<std::uint32_t> target_slot_;  // by target: its slot
  std::vector<float> sorted_x_, sorted_y_, sorted_z_;  // positions in slot order
  std::vector<std::uint32_t> sorted_source_;           // the caller's particle of each slot
  std::vector<PointImage> sorted_image_;               // with images: each slot's table entry
  std::vector<CellKey> cell_keys_;                     // non-empty cells, ascending
  // Per cell: whether it holds a target. Only those get neighbour runs: a cell of images alone
  // (or of sources alone, with query targets) is never asked, and a small periodic box has
  // mostly such cells (one atom of a primitive cell with a cutoff of 5: 1 of 45 cells).
  std::vector<bool> holds_target_;
  std::vector<std::uint32_t> cell_start_;        // cell c's sources: slots [start[c], start[c+1])
  std::vector<std::uint32_t> cell_of_particle_;  // particle index -> cell
  struct SlotRange {
    std::uint32_t begin, end;
  };
  std::vector<std::uint64_t> run_offsets_;  // cell c's candidates: runs_[offsets[c], offsets[c+1])
  std::vector<SlotRange> runs_;
};

}  // namespace

std::unique_ptr<Method> make_cell_list_cpu() {
  return std::make_unique<CellListCpu>();
}

}  // namespace raycut::detail
