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
    plan_misfit_ = points.reuse.misfit;
    PlannedBox watch;
    if (points.reuse.misfit) {
      // The recorded plan again (Engine::set_reuse_plan): its box watched on the device, by the
      // build's first kernel.
      for (int a = 0; a < 3; ++a) watch.lo[a] = planned_lo_[a], watch.hi[a] = planned_hi_[a];
      watch.misfit = points.reuse.misfit;
    } else {
      float lo[3], hi[3];
      box_.compute(points.xyz, n, lo, hi, stream_);
      // Points with images: cells as wide as the band's reach, so that every pair the exact
      // decision may take is offered (the CPU cell list widens its cells the same way).
      const float reach = points.images.exact ? search_reach(cutoff, *points.images.exact) : cutoff;
      has_parking_ = points.reuse.record;
      if (has_parking_) plan_room(lo, hi, reach);
      plan_ = plan_grid(
          policy_,
          GridInput{has_parking_ ? points.reuse.planned_size : n, points.targets, points.systems},
          lo, hi, reach);
    }
    plan_.geometry.system = points.systems > 1 ? points.system : nullptr;
    tables_.build(points.xyz, static_cast<std::uint32_t>(n), plan_, watch, stream_);
    if (points.targets < n)
      tables_.select_targets(static_cast<std::uint32_t>(points.targets), stream_);
    if (images_.active())  // the traversal indexes images by slot
      images_.deferred = tables_.slot_images(images_.image);
    build_timer_.stop(stream_);
  }

  bool reuses_plans() const override { return true; }
  bool parking(ParkingPlace& place) const override {
    place = parking_;
    return has_parking_;
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
  // The plan that later builds reuse: its box, and where their spare slots park.
  float planned_lo_[3] = {0, 0, 0}, planned_hi_[3] = {0, 0, 0};
  ParkingPlace parking_;
  bool has_parking_ = false;

  // A box [lo, hi] that later builds reuse: half the reach wider on every side (and 2^-12 of
  // its size, for the rounding of far coordinates), then longer in x by a gap of at least three
  // reaches and the sheet of cells where the spare slots park: no real point's search reaches
  // them, and few of its cells are visited.
  void plan_room(float lo[3], float hi[3], float reach) {
    for (int a = 0; a < 3; ++a) {
      const float margin =
          0.5f * reach + std::ldexp(std::max(std::fabs(lo[a]), std::fabs(hi[a])), -12);
      lo[a] -= margin;
      hi[a] += margin;
    }
    for (int a = 0; a < 3; ++a) planned_lo_[a] = lo[a], planned_hi_[a] = hi[a];
    parking_.x = hi[0] + 4 * reach;
    for (int a = 0; a < 2; ++a) parking_.lo[a] = lo[a + 1], parking_.hi[a] = hi[a + 1];
    hi[0] = parking_.x;
    planned_hi_[0] = hi[0];
  }
};

}  // namespace

std::unique_ptr<Method> make_grid_with(const GridPolicy& policy) {
  return std::make_unique<Grid>(policy);
}
std::unique_ptr<Method> make_grid() {
  return make_grid_with(GridPolicy{});
}

}  // namespace raycut::detail::cuda
