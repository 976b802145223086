// Method 0, the oracle: every pair, the shared predicate, nothing clever.
#include <vector>

#include "core/method.hpp"
#include "cpu/host_method.hpp"

namespace raycut::detail {
namespace {

class BruteForceCpu final : public HostMethod<BruteForceCpu> {
 public:
  auto candidates() const {
    return [this](std::size_t, auto&& f) {
      for (std::size_t j = 0; j < xyz_.size() / 3; ++j) f(j, &xyz_[3 * j]);
    };
  }

  void build(const float* xyz, std::size_t n, float cutoff) override {
    require_indexable(n, "brute-force");
    xyz_.assign(xyz, xyz + 3 * n);
    set_positions(xyz_.data(), n, cutoff);
  }

 private:
  std::vector<float> xyz_;
};

}  // namespace

std::unique_ptr<Method> make_brute_force_cpu() {
  return std::make_unique<BruteForceCpu>();
}

}  // namespace raycut::detail
