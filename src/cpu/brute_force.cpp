// Method 0, the oracle: every pair, the shared predicate, nothing clever.
#include <string>
#include <vector>

#include "core/method.hpp"
#include "cpu/host_pairs.hpp"
#include "raycut/error.hpp"

namespace raycut::detail {
namespace {

class BruteForceCpu final : public Method {
  // Defined first: the public members use its deduced type.
  std::size_t size() const { return xyz_.size() / 3; }
  auto all_pairs() const {
    return [this](std::size_t, auto&& f) {
      for (std::size_t j = 0; j < size(); ++j) f(j, &xyz_[3 * j]);
    };
  }

 public:
  MemorySpace space() const override { return MemorySpace::host; }

  void build(const float* xyz, std::size_t n, float cutoff) override {
    if (n >= (std::size_t{1} << 32))  // NeighbourList::indices is uint32
      throw Error(ErrorCode::invalid_argument,
                  "brute-force supports fewer than 2^32 = 4294967296 particles (32-bit "
                  "indices), got N = " +
                      std::to_string(n));
    xyz_.assign(xyz, xyz + 3 * n);
    cutoff_ = cutoff;
  }

  void compute(Kernel kernel, const KernelOptions& options) override {
    results_ = host_compute(size(), xyz_.data(), cutoff_, kernel, options, all_pairs());
  }
  Results results() const override { return results_; }
  ResultsView results_view() const override { return view_of(results_); }
  NeighbourList neighbours() override {
    return host_neighbours(size(), xyz_.data(), cutoff_, all_pairs());
  }

 private:
  std::vector<float> xyz_;
  float cutoff_ = 0;
  Results results_;
};

}  // namespace

std::unique_ptr<Method> make_brute_force_cpu() {
  return std::make_unique<BruteForceCpu>();
}

}  // namespace raycut::detail
