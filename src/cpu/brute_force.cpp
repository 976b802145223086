// Method 0, the oracle: every pair, the shared predicate, nothing clever.
#include <vector>

#include "core/method.hpp"
#include "cpu/host_method.hpp"

namespace raycut::detail {
namespace {

class BruteForceCpu final : public HostMethod<BruteForceCpu> {
 public:
  // Every point of the target's system.
  auto candidates() const {
    return [this](std::size_t i, auto&& f) {
      const std::size_t points = xyz_.size() / 3;
      for (std::size_t j = 0; j < points; ++j)
        if (system_.empty() || system_[j] == system_[i]) f(j, &xyz_[3 * j]);
    };
  }

  void build(const float* xyz, std::size_t n, float cutoff) override {
    build_points(Points::plain(xyz, n), cutoff);
  }
  std::string points_unsupported() const override { return {}; }
  void build_points(const Points& points, float cutoff) override {
    require_indexable(points.size, "brute-force");
    xyz_.assign(points.xyz, points.xyz + 3 * points.size);
    system_.clear();
    if (points.systems > 1) system_.assign(points.system, points.system + points.size);
    set_positions(xyz_.data(), points.size, cutoff, points.targets, points.images);
  }

 private:
  std::vector<float> xyz_;
  std::vector<std::uint32_t> system_;  // per point (batches); empty: one system
};

}  // namespace

std::unique_ptr<Method> make_brute_force_cpu() {
  return std::make_unique<BruteForceCpu>();
}

}  // namespace raycut::detail
