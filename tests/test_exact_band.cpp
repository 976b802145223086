// The pieces of the exact periodic decision that the CPU and CUDA passes share, on the host: the
// float band (set_float_band, rounding_bound, band_reach), the extent of a point's images that
// the device expansion computes without enumerating them (image_extent), the decision itself
// (in_range_exact, in_range_banded) and the policy each functor gets (with_images). Runs
// without a GPU.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <type_traits>
#include <vector>

#include "core/image_frame.hpp"
#include "core/images.hpp"
#include "raycut/box.hpp"
#include "raycut/detail/images.hpp"
#include "raycut/kernels.hpp"

namespace {

using raycut::detail::ExactImages;
using raycut::detail::PointImage;

double band_slack(double cutoff, double rounding) {
  return raycut::detail::float_band_slack(cutoff, rounding);
}

TEST(FloatBand, FloatsBracketTheSlackOneStepOutwards) {
  for (const double cutoff : {1.0 / 16, 0.7, 1.0, 2.5, 3.0, 31.9}) {
    for (const double extent_ratio : {1.0, 10.0, 100.0, 127.0, 129.0, 1e3, 1e6}) {
      const double rounding = raycut::detail::rounding_bound(extent_ratio * cutoff);
      ExactImages e;
      raycut::detail::set_float_band(e, cutoff, rounding);
      const double c2 = cutoff * cutoff, slack = band_slack(cutoff, rounding);
      SCOPED_TRACE("cutoff " + std::to_string(cutoff) + ", extent " + std::to_string(extent_ratio) +
                   " C");
      EXPECT_EQ(e.cutoff_squared, c2);
      EXPECT_EQ(e.rounding, rounding);
      EXPECT_EQ(e.exact_vectors, rounding > std::ldexp(cutoff, -16));
      // Out for certain from float_out: at or above c2 + slack, by at most one float step.
      EXPECT_GE(static_cast<double>(e.float_out), c2 + slack);
      EXPECT_LT(static_cast<double>(std::nextafter(e.float_out, 0.0f)), c2 + slack);
      if (e.exact_vectors) {
        EXPECT_EQ(e.float_in, 0.0f);  // every pair from the double vector
      } else {
        EXPECT_LE(static_cast<double>(e.float_in), c2 - slack);
        EXPECT_GT(static_cast<double>(std::nextafter(e.float_in, INFINITY)), c2 - slack);
      }
      // The reach a search must offer: every float r2 below float_out.
      const double reach = raycut::detail::band_reach(e);
      EXPECT_GT(reach * reach, static_cast<double>(e.float_out));
      EXPECT_LT(reach * reach, static_cast<double>(e.float_out) * (1 + 1e-5));
    }
  }
}

TEST(FloatBand, ExactVectorsFromExtentsOver128Cutoffs) {
  // rounding_bound(x) = 2^-23 x: over 2^-16 C from x = 2^7 C.
  ExactImages e;
  raycut::detail::set_float_band(e, 1.0, raycut::detail::rounding_bound(127.0));
  EXPECT_FALSE(e.exact_vectors);
  raycut::detail::set_float_band(e, 1.0, raycut::detail::rounding_bound(129.0));
  EXPECT_TRUE(e.exact_vectors);
}

TEST(FloatBand, RoundingBoundCoversTheFloatRounding) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(-1.0, 1.0);
  for (const double extent : {1e-3, 1.0, 3.7, 1e4, 1e7}) {
    const double bound = raycut::detail::rounding_bound(extent);
    for (int k = 0; k < 10000; ++k) {
      const double x = extent * unit(rng);
      ASSERT_LE(2 * std::fabs(static_cast<double>(static_cast<float>(x)) - x), bound)
          << "x = " << x << ", extent " << extent;
    }
  }
}

// A frame as the expansion makes it (plan_images validates the box and sets reach), its origin
// set from a point as for a system of a batch.
raycut::detail::ImageFrame frame_of(const raycut::Box& box, double cutoff, const double* first) {
  raycut::Systems systems;
  systems.box = box;
  raycut::detail::ImageFrame frame = raycut::detail::plan_images(systems, 1, cutoff).frames[0];
  if (first) raycut::detail::system_origin(frame, first);
  return frame;
}

TEST(ImageExtent, BoundsTheEmittedFloatPointsTightly) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  for (int trial = 0; trial < 300; ++trial) {
    raycut::Box box;
    const double length = std::pow(10.0, 3 * unit(rng));
    for (int k = 0; k < 3; ++k) {
      box.cell[k][k] = length * (0.5 + unit(rng));
      for (int m = 0; m < k; ++m) box.cell[k][m] = 0.6 * length * (2 * unit(rng) - 1);
      box.pbc[k] = unit(rng) < 0.8;
    }
    const double cutoff = length * (0.05 + 0.9 * unit(rng));
    double x[3];
    for (double& v : x) v = length * (40 * unit(rng) - 20);
    double origin_point[3];
    for (double& v : origin_point) v = length * (40 * unit(rng) - 20);
    const raycut::detail::ImageFrame frame =
        frame_of(box, cutoff, trial % 2 == 0 ? origin_point : nullptr);
    const raycut::detail::WrappedPoint w = raycut::detail::wrap_point(frame, x);
    ASSERT_TRUE(w.ok);
    double emitted = 0;
    raycut::detail::for_each_image(frame, w, true, [&](const int*, const float p[3]) {
      for (int c = 0; c < 3; ++c)
        emitted = std::fmax(emitted, std::fabs(static_cast<double>(p[c])));
    });
    const double extent = raycut::detail::image_extent(frame, w);
    SCOPED_TRACE("trial " + std::to_string(trial));
    // A bound on the float points up to their own rounding (half an ulp), and attained.
    EXPECT_LE(emitted, extent * (1 + std::ldexp(1.0, -24)));
    EXPECT_GE(emitted, extent * (1 - std::ldexp(1.0, -23)));
  }
}

// Two particles across the x face of a box 10^4 wide, `gap` apart through it (cutoff 1):
// particle 1 at 9999.5, particle 0 at gap - 0.5, so x_1 - a - x_0 = -gap. Points: 0 and 1 the
// particles, 2 the image of 1 with T = (-1, 0, 0), 3 a query point on particle 0. The band as
// for points of magnitude up to `extent`.
struct FacePair {
  std::vector<float> sources, queries;
  std::vector<PointImage> image;
  std::vector<double> cells;
  ExactImages e;
  explicit FacePair(double gap, double extent = 100) {
    const double length = 1e4;
    const auto x0 = static_cast<float>(gap - 0.5);
    sources = {x0, 10, 10, 9999.5f, 10, 10};
    queries = {0, 0, 0, 0, 0, 0, 0, 0, 0, x0, 10, 10};
    image = {{0, {0, 0, 0}}, {1, {0, 0, 0}}, {1, {-1, 0, 0}}, {raycut::detail::not_a_source, {}}};
    cells = {length, 0, 0, 0, length, 0, 0, 0, length};
    e.sources = sources.data();
    e.queries = queries.data();
    e.image = image.data();
    e.cells = cells.data();
    raycut::detail::set_float_band(e, 1.0, raycut::detail::rounding_bound(extent));
  }
  double exact_gap() const {  // |x_1 - a - x_0| in double
    return std::fabs(static_cast<double>(sources[3]) - 1e4 - static_cast<double>(sources[0]));
  }
};

TEST(InRangeExact, DecidesFromTheCallersPositionsInDouble) {
  for (const double gap : {1 - 1e-6, 1 - 3e-7, 1 + 3e-7, 1 + 1e-6, 0.5, 1.5}) {
    FacePair f(gap);
    raycut::Vec3 r{123, 0, 0};
    float r2 = 123;
    const bool in = raycut::detail::in_range_exact(f.e, 0, 2, r, r2);
    const double d = f.exact_gap();
    EXPECT_EQ(in, d < 1.0) << "gap " << gap << ", exact " << d;
    if (in) {  // r and r2 from the double vector, rounded once
      EXPECT_EQ(r.x, static_cast<float>(-d));
      EXPECT_EQ(r.y, 0.0f);
      EXPECT_EQ(r2, r.x * r.x);
    }
    // The mirror: particle 1 (point 1, T = 0) and particle 0's image at +a, as a point with
    // T = (1, 0, 0): the same decision (the double vector is exactly antisymmetric).
    f.image.push_back({0, {1, 0, 0}});
    f.e.image = f.image.data();
    raycut::Vec3 m{};
    float m2 = 0;
    EXPECT_EQ(raycut::detail::in_range_exact(f.e, 1, 4, m, m2), in);
    if (in) {
      EXPECT_EQ(m.x, -r.x);
    }
  }
}

TEST(InRangeExact, QueryTargetsReadTheirOwnPositionAndAreNeverSources) {
  FacePair f(1 - 1e-6);
  raycut::Vec3 r{};
  float r2 = 0;
  // Query point 3 sits on particle 0: its candidate, the image of particle 1, is in range.
  EXPECT_TRUE(raycut::detail::in_range_exact(f.e, 3, 2, r, r2));
  EXPECT_EQ(r.x, static_cast<float>(-f.exact_gap()));
  // A query point as a candidate: never a pair.
  EXPECT_FALSE(raycut::detail::in_range_exact(f.e, 0, 3, r, r2));
}

TEST(InRangeBanded, FloatOutsideTheBandDoubleInside) {
  FacePair f(1 - 1e-6);
  ASSERT_FALSE(f.e.exact_vectors);
  ASSERT_LT(f.e.float_in, 1.0f);
  ASSERT_GT(f.e.float_out, 1.0f);
  // Below the band: in, the float r kept.
  raycut::Vec3 r{0.25f, 0, 0};
  float r2 = 0.0625f;
  EXPECT_TRUE(raycut::detail::in_range_banded(f.e, 0, 2, r, r2));
  EXPECT_EQ(r.x, 0.25f);
  // At or above float_out: out, whatever the double says.
  r2 = f.e.float_out;
  EXPECT_FALSE(raycut::detail::in_range_banded(f.e, 0, 2, r, r2));
  // In the band: the double decides and gives r.
  r = {-1, 0, 0};
  r2 = 1;
  EXPECT_TRUE(raycut::detail::in_range_banded(f.e, 0, 2, r, r2));
  EXPECT_EQ(r.x, static_cast<float>(-f.exact_gap()));
  FacePair out(1 + 1e-6);
  r = {-1, 0, 0};
  r2 = 1;
  EXPECT_FALSE(raycut::detail::in_range_banded(out.e, 0, 2, r, r2));
}

TEST(InRangeBanded, ExactVectorsTakeEveryPairFromTheDoubles) {
  FacePair f(0.5, 1e6);
  ASSERT_TRUE(f.e.exact_vectors);
  raycut::Vec3 r{-0.4375f, 0, 0};  // a float r off by the box's rounding
  float r2 = r.x * r.x;
  EXPECT_TRUE(raycut::detail::in_range_banded(f.e, 0, 2, r, r2));
  EXPECT_EQ(r.x, static_cast<float>(-f.exact_gap()));
}

// Functors as with_images sees them: one reading neither j nor S, one reading j.
struct ReadsNothing {
  using Accumulator = int;
  RAYCUT_HD void operator()(int& acc, std::uint32_t, raycut::Vec3, float) const { ++acc; }
  RAYCUT_HD void finish(std::uint32_t, int&) const {}
};
struct ReadsSource {
  using Accumulator = int;
  RAYCUT_HD void operator()(int& acc, std::uint32_t, std::uint32_t j, raycut::Vec3, float) const {
    acc += static_cast<int>(j);
  }
  RAYCUT_HD void finish(std::uint32_t, int&) const {}
};

enum class Policy { none, with_images, unread_images };
template <class F>
Policy policy_of(const raycut::detail::PairPass& pass) {
  Policy chosen{};
  raycut::detail::with_images<F>(pass, [&](const auto& images) {
    using I = std::decay_t<decltype(images)>;
    chosen = std::is_same_v<I, raycut::detail::NoImages>     ? Policy::none
             : std::is_same_v<I, raycut::detail::WithImages> ? Policy::with_images
                                                             : Policy::unread_images;
    if constexpr (I::banded) {
      EXPECT_EQ(images.exact.float_out, pass.images.exact->float_out);
    }
  });
  return chosen;
}

TEST(WithImages, PolicyPerFunctorAndTheBandWithEveryImage) {
  FacePair f(1);
  raycut::detail::PairPass pass;
  pass.method = "test";
  EXPECT_EQ(policy_of<ReadsNothing>(pass), Policy::none);
  EXPECT_EQ(policy_of<ReadsSource>(pass), Policy::none);
  pass.images.image = f.image.data();
  pass.images.exact = &f.e;
  EXPECT_EQ(policy_of<ReadsNothing>(pass), Policy::unread_images);
  EXPECT_EQ(policy_of<ReadsSource>(pass), Policy::with_images);
  pass.images.candidates_are_sources = false;  // a query point may be offered: the tables
  EXPECT_EQ(policy_of<ReadsNothing>(pass), Policy::with_images);
  // Points with images always come with their exact decision.
  pass.images.exact = nullptr;
  try {
    policy_of<ReadsNothing>(pass);
    FAIL() << "images without ExactImages accepted";
  } catch (const raycut::Error& e) {
    EXPECT_EQ(e.code(), raycut::ErrorCode::internal);
    EXPECT_NE(std::string(e.what()).find("'test'"), std::string::npos) << e.what();
  }
}

}  // namespace
