// Method 0, the oracle: every pair, the shared predicate, nothing clever.
#include <vector>

#include "core/method.hpp"
#include "cpu/host_method.hpp"

namespace raycut::detail {
namespace {

class BruteForceCpu final : public HostMethod<BruteForceCpu> {
 public:
  // Every point of the target's system: one run, the points grouped by system.
  std::size_t candidate_runs(std::size_t i, CandidateRun* out) const {
    const std::uint32_t s = system_.empty() ? 0 : system_[i];
    const std::uint32_t first = system_start_[s];
    out[0] = {x_.data() + first,
              y_.data() + first,
              z_.data() + first,
              order_.empty() ? nullptr : order_.data() + first,
              nullptr,
              nullptr,
              first,
              0,
              system_start_[s + 1] - first};
    return 1;
  }

  void build(const float* xyz, std::size_t n, float cutoff) override {
    build_points(Points::plain(xyz, n), cutoff);
  }
  std::string points_unsupported() const override { return {}; }
  void build_points(const Points& points, float cutoff) override {
    const std::size_t n = points.size;
    require_indexable(n, "brute-force");
    xyz_.assign(points.xyz, points.xyz + 3 * n);
    system_.clear();
    order_.clear();
    system_start_.assign({0, static_cast<std::uint32_t>(n)});
    if (points.systems > 1) {
      // A counting sort of the points by system (stable).
      system_.assign(points.system, points.system + n);
      system_start_.assign(points.systems + 1, 0);
      for (const std::uint32_t s : system_) ++system_start_[s + 1];
      for (std::size_t s = 0; s < points.systems; ++s) system_start_[s + 1] += system_start_[s];
      order_.resize(n);
      std::vector<std::uint32_t> next(system_start_.begin(), system_start_.end() - 1);
      for (std::size_t k = 0; k < n; ++k)
        order_[next[system_[k]]++] = static_cast<std::uint32_t>(k);
    }
    x_.assign(n + CandidateRun::padding, 0.0f);  // padded: a run reads whole vectors
    y_.assign(n + CandidateRun::padding, 0.0f);
    z_.assign(n + CandidateRun::padding, 0.0f);
    for (std::size_t t = 0; t < n; ++t) {
      const float* p = &xyz_[3 * (order_.empty() ? t : order_[t])];
      x_[t] = p[0];
      y_[t] = p[1];
      z_[t] = p[2];
    }
    set_positions(xyz_.data(), n, cutoff, points.targets, points.images);
  }

 private:
  std::vector<float> xyz_;                   // the caller's order: the targets
  std::vector<float> x_, y_, z_;             // grouped by system
  std::vector<std::uint32_t> order_;         // grouped slot -> point; empty: one system
  std::vector<std::uint32_t> system_;        // per point (batches); empty: one system
  std::vector<std::uint32_t> system_start_;  // system s: slots [start[s], start[s + 1])
};

}  // namespace

std::unique_ptr<Method> make_brute_force_cpu() {
  return std::make_unique<BruteForceCpu>();
}

}  // namespace raycut::detail
