// CPU cell list with memory O(N) whatever the distribution: particles are sorted by cell key and
// only non-empty cells are stored (sorted keys + start offsets), so a far outlier or a sphere
// surface never allocates a dense grid. Each cell's up-to-27 non-empty neighbours are found
// once, by binary search, at build time.
#include <algorithm>
#include <cstdint>
#include <numeric>
#include <vector>

#include "raycut/detail/cell_grid.hpp"
#include "core/method.hpp"
#include "cpu/host_method.hpp"

namespace raycut::detail {
namespace {

class CellListCpu final : public HostMethod<CellListCpu> {
 public:
  // Candidates of target i: the particles of the non-empty cells around its own.
  auto candidates() const {
    return [this](std::size_t i, auto&& f) {
      const std::uint32_t c = cell_of_particle_[i];
      for (std::size_t e = neighbour_offsets_[c]; e < neighbour_offsets_[c + 1]; ++e) {
        const std::uint32_t nc = neighbour_cells_[e];
        for (std::uint32_t s = cell_start_[nc]; s < cell_start_[nc + 1]; ++s)
          f(order_[s], &sorted_xyz_[3 * std::size_t{s}]);
      }
    };
  }

  void build(const float* xyz, std::size_t n, float cutoff) override {
    xyz_.assign(xyz, xyz + 3 * n);
    set_positions(xyz_.data(), n, cutoff);
    float lo[3], hi[3];
    bounding_box(lo, hi);
    grid_ = make_cell_grid(lo, hi, cutoff);

    // Sort particles by cell key.
    std::vector<std::uint64_t> keys(n);
#pragma omp parallel for schedule(static)
    for (std::size_t i = 0; i < n; ++i)
      keys[i] = grid_.key_of(xyz[3 * i], xyz[3 * i + 1], xyz[3 * i + 2]);
    order_.resize(n);
    std::iota(order_.begin(), order_.end(), 0u);
    std::sort(order_.begin(), order_.end(), [&](std::uint32_t a, std::uint32_t b) {
      return keys[a] < keys[b] || (keys[a] == keys[b] && a < b);
    });
    sorted_xyz_.resize(3 * n);
    for (std::size_t s = 0; s < n; ++s)
      std::copy_n(&xyz[3 * std::size_t{order_[s]}], 3, &sorted_xyz_[3 * s]);

    // Compact the non-empty cells.
    cell_keys_.clear();
    cell_start_.clear();
    cell_of_particle_.resize(n);
    for (std::size_t s = 0; s < n; ++s) {
      const std::uint64_t k = keys[order_[s]];
      if (cell_keys_.empty() || cell_keys_.back() != k) {
        cell_keys_.push_back(k);
        cell_start_.push_back(static_cast<std::uint32_t>(s));
      }
      cell_of_particle_[order_[s]] = static_cast<std::uint32_t>(cell_keys_.size() - 1);
    }
    cell_start_.push_back(static_cast<std::uint32_t>(n));
    find_neighbour_cells();
  }

 private:
  std::size_t size() const {
    return order_.size();
  }

  void bounding_box(float lo[3], float hi[3]) const {
    for (int a = 0; a < 3; ++a) lo[a] = hi[a] = xyz_[a];
    for (std::size_t i = 0; i < xyz_.size(); i += 3) {
      for (int a = 0; a < 3; ++a) {
        lo[a] = std::min(lo[a], xyz_[i + a]);
        hi[a] = std::max(hi[a], xyz_[i + a]);
      }
    }
  }

  // CSR over cells: the non-empty cells within `reach` of each cell (itself included).
  void find_neighbour_cells() {
    const std::size_t cells = cell_keys_.size();
    std::vector<std::vector<std::uint32_t>> per_cell(cells);
#pragma omp parallel for schedule(dynamic, 64)
    for (std::size_t c = 0; c < cells; ++c) {
      const std::uint64_t k = cell_keys_[c];
      const std::int64_t ix = static_cast<std::int64_t>(k % grid_.dims[0]);
      const std::int64_t iy = static_cast<std::int64_t>((k / grid_.dims[0]) % grid_.dims[1]);
      const std::int64_t iz = static_cast<std::int64_t>(k / grid_.dims[0] / grid_.dims[1]);
      for (std::int64_t z = iz - 1; z <= iz + 1; ++z)
        for (std::int64_t y = iy - 1; y <= iy + 1; ++y)
          for (std::int64_t x = ix - 1; x <= ix + 1; ++x) {
            if (x < 0 || y < 0 || z < 0 || x >= grid_.dims[0] || y >= grid_.dims[1] ||
                z >= grid_.dims[2])
              continue;
            const std::uint64_t nk = grid_.key(x, y, z);
            auto it = std::lower_bound(cell_keys_.begin(), cell_keys_.end(), nk);
            if (it != cell_keys_.end() && *it == nk)
              per_cell[c].push_back(static_cast<std::uint32_t>(it - cell_keys_.begin()));
          }
    }
    neighbour_offsets_.assign(cells + 1, 0);
    for (std::size_t c = 0; c < cells; ++c)
      neighbour_offsets_[c + 1] = neighbour_offsets_[c] + per_cell[c].size();
    neighbour_cells_.resize(neighbour_offsets_[cells]);
    for (std::size_t c = 0; c < cells; ++c)
      std::copy(per_cell[c].begin(), per_cell[c].end(),
                neighbour_cells_.begin() + neighbour_offsets_[c]);
  }

  std::vector<float> xyz_;
  CellGrid grid_;
  std::vector<std::uint32_t> order_;             // sorted slot -> particle index
  std::vector<float> sorted_xyz_;                // positions in sorted order
  std::vector<std::uint64_t> cell_keys_;         // non-empty cells, ascending
  std::vector<std::uint32_t> cell_start_;        // cell c holds slots [start[c], start[c+1])
  std::vector<std::uint32_t> cell_of_particle_;  // particle index -> cell
  std::vector<std::uint64_t> neighbour_offsets_;
  std::vector<std::uint32_t> neighbour_cells_;
};

}  // namespace

std::unique_ptr<Method> make_cell_list_cpu() {
  return std::make_unique<CellListCpu>();
}

}  // namespace raycut::detail
