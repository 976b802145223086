// grid: the production CUDA grid. Memory O(N) whatever the distribution, exact full semantics.
// A build is: the bounding box (read back), a plan (grid_policy.hpp: cell widths, table layout,
// kernel), the tables (grid_tables.cuh); every functor then runs through the one traversal of
// include/raycut/detail/cuda/grid_pass.cuh. docs/grid.md explains each choice.
#include <string>

#include "cuda/device_results.cuh"
#include "cuda/grid_common.cuh"
#include "cuda/grid_policy.hpp"
#include "cuda/grid_tables.cuh"
#include "cuda/methods.hpp"
#include "raycut/detail/cuda/grid_pass.cuh"
#include "raycut/predicate.hpp"

namespace raycut::detail::cuda {
namespace {

class Grid final : public CudaPairMethod<Grid> {
 public:
  explicit Grid(const GridPolicy& policy) : policy_(policy) {}

  void build(const float* xyz, std::size_t n, float cutoff) override {
    if (n >= UINT32_MAX)
      throw Error(ErrorCode::invalid_argument,
                  "grid handles at most 2^32 - 2 particles, got " + std::to_string(n));
    n_ = n;
    cutoff_squared_ = squared_cutoff(cutoff);
    build_timer_.start(stream_);
    float lo[3], hi[3];
    box_.compute(xyz, n, lo, hi, stream_);
    plan_ = plan_grid(policy_, n, lo, hi, cutoff);
    tables_.build(xyz, static_cast<std::uint32_t>(n), plan_, stream_);
    build_timer_.stop(stream_);
  }

  std::size_t size() const { return n_; }
  PairPass pair_pass() const override {
    PairPass pass;
    pass.kind = PassKind::grid;
    pass.n = n_;
    pass.cutoff_squared = cutoff_squared_;
    pass.grid = tables_.pass(plan_);
    return pass;
  }
  template <class F>
  void run(const F& f) const {
    run_grid(pair_pass(), f, stream_);
  }

 private:
  GridPolicy policy_;
  std::size_t n_ = 0;
  float cutoff_squared_ = 0;
  GridPlan plan_;
  BoundingBox box_;
  GridTables tables_;
};

}  // namespace

std::unique_ptr<Method> make_grid_with(const GridPolicy& policy) {
  return std::make_unique<Grid>(policy);
}
std::unique_ptr<Method> make_grid() {
  return make_grid_with(GridPolicy{});
}

}  // namespace raycut::detail::cuda
