// grid: the production CUDA grid. Memory O(N) whatever the distribution, exact full semantics.
// A build is: the bounding box (read back), a plan (grid_policy.hpp: cell widths, table layout,
// kernel), the tables (grid_tables.cuh); every functor then runs through the one traversal of
// include/raycut/detail/cuda/grid_pass.cuh. docs/grid.md explains each choice.
#include <algorithm>
#include <cmath>
#include <string>

#include "core/images.hpp"
#include "core/list_functors.hpp"

#include "cuda/device_results.cuh"
#include "cuda/grid_common.cuh"
#include "cuda/grid_list_passes.hpp"
#include "cuda/grid_policy.hpp"
#include "cuda/grid_tables.cuh"
#include "cuda/methods.hpp"
#include "raycut/detail/cuda/grid_pass.cuh"
#include "raycut/predicate.hpp"

namespace raycut::detail::cuda {

RAYCUT_GRID_LIST_FUNCTORS(RAYCUT_GRID_DECLARE_RUN)

namespace {

// The cutoff, or the band's reach (band_reach) when wider, rounded up to a float.
float search_reach(float cutoff, const ExactImages& exact) {
  const double reach = std::max<double>(cutoff, band_reach(exact));
  const auto rounded = static_cast<float>(reach);
  return static_cast<double>(rounded) >= reach ? rounded : std::nextafter(rounded, INFINITY);
}

class Grid final : public CudaPairMethod<Grid> {
 public:
  explicit Grid(const GridPolicy& policy) : policy_(policy) {}

  void build(const float* xyz, std::size_t n, float cutoff) override {
    build_points(Points::plain(xyz, n), cutoff);
  }

  std::string points_unsupported() const override { return {}; }
  void build_points(const Points& points, float cutoff) override {
    const std::size_t n = points.size;
    if (n >= UINT32_MAX)
      throw Error(ErrorCode::invalid_argument,
                  "grid handles at most 2^32 - 2 points, got " + std::to_string(n));
    n_ = points.targets;
    points_ = n;
    images_ = points.images;
    cutoff_squared_ = squared_cutoff(cutoff);
    build_timer_.start(stream_);
    float lo[3], hi[3];
    box_.compute(points.xyz, n, lo, hi, stream_);
    // Points with images: cells as wide as the band's reach, so that every pair the exact
    // decision may take is offered (the CPU cell list widens its cells the same way).
    const float reach = points.images.exact ? search_reach(cutoff, *points.images.exact) : cutoff;
    plan_ = plan_grid(policy_, GridInput{n, points.targets, points.systems}, lo, hi, reach);
    plan_.geometry.system = points.systems > 1 ? points.system : nullptr;
    tables_.build(points.xyz, static_cast<std::uint32_t>(n), plan_, stream_);
    if (points.targets < n)
      tables_.select_targets(static_cast<std::uint32_t>(points.targets), stream_);
    if (images_.active())  // the traversal indexes images by slot
      images_.deferred = tables_.slot_images(images_.image);
    build_timer_.stop(stream_);
  }

  std::size_t size() const { return n_; }
  PairPass pair_pass() const override {
    PairPass pass;
    pass.kind = PassKind::grid;
    pass.n = n_;
    pass.points = points_;
    pass.images = images_;
    pass.cutoff_squared = cutoff_squared_;
    pass.grid = tables_.pass(plan_);
    if (n_ == points_) pass.grid.targets = nullptr;
    return pass;
  }
  template <class F>
  void run(const F& f) const {
    run_without_idle_cutoffs(f, [&](const auto& g) { run_grid(pair_pass(), g, stream_); });
  }

 private:
  GridPolicy policy_;
  std::size_t n_ = 0, points_ = 0;  // targets, points
  ImageTables images_;
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
