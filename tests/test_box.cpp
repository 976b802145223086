// Periodic boxes (include/raycut/box.hpp): validation, face widths against hand-computed values,
// image ranges checked by brute force, and wrapping round trips far from the cell.
#include <gtest/gtest.h>

#include <array>
#include <cmath>
#include <cstdint>
#include <functional>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "error_helpers.hpp"
#include "raycut/box.hpp"
#include "raycut/error.hpp"

namespace raycut {
namespace {

Box make_box(std::array<std::array<double, 3>, 3> rows,
             std::array<bool, 3> pbc = {true, true, true}) {
  Box box;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) box.cell[r][c] = rows[r][c];
    box.pbc[r] = pbc[r];
  }
  return box;
}

std::string refused(const std::function<void()>& action) {
  return raycut_test::error_message(ErrorCode::invalid_argument, action);
}

using raycut_test::contains;

const double inf = std::numeric_limits<double>::infinity();
const double s3 = std::sqrt(3.0);

TEST(Box, OpenIsTheDefault) {
  const Box box;
  EXPECT_TRUE(box.is_open());
  EXPECT_FALSE(box.periodic());
  EXPECT_EQ(box, Box::open());
  validate(box);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(face_width(box, k), inf);
  EXPECT_TRUE(minimum_image_ok(box, 1e30));
  EXPECT_EQ(image_range(box, 1e30), (std::array<int, 3>{0, 0, 0}));
  const Wrapped w = wrap(box, {1e30, -5, 3});
  EXPECT_EQ(w.x, (std::array<double, 3>{1e30, -5, 3}));
  EXPECT_EQ(w.shift, (std::array<std::int32_t, 3>{0, 0, 0}));
  // A cell without periodic axes is not open, but has no images.
  Box kept = Box::orthorhombic(1, 2, 3, false, false, false);
  EXPECT_FALSE(kept.is_open());
  EXPECT_EQ(image_range(kept, 10), (std::array<int, 3>{0, 0, 0}));
}

TEST(Box, CubicAndOrthorhombicWidths) {
  const Box cube = Box::orthorhombic(2, 2, 2);
  for (int k = 0; k < 3; ++k) EXPECT_DOUBLE_EQ(face_width(cube, k), 2);
  EXPECT_TRUE(minimum_image_ok(cube, 1));
  EXPECT_FALSE(minimum_image_ok(cube, std::nextafter(1.0, 2.0)));
  EXPECT_EQ(image_range(cube, 1), (std::array<int, 3>{1, 1, 1}));
  EXPECT_EQ(image_range(cube, 2), (std::array<int, 3>{1, 1, 1}));
  EXPECT_EQ(image_range(cube, 2.0001), (std::array<int, 3>{2, 2, 2}));
  EXPECT_EQ(image_range(cube, 7), (std::array<int, 3>{4, 4, 4}));

  const Box ortho = Box::orthorhombic(1, 2, 3);
  EXPECT_DOUBLE_EQ(face_width(ortho, 0), 1);
  EXPECT_DOUBLE_EQ(face_width(ortho, 1), 2);
  EXPECT_DOUBLE_EQ(face_width(ortho, 2), 3);
  EXPECT_EQ(image_range(ortho, 2.5), (std::array<int, 3>{3, 2, 1}));
  EXPECT_TRUE(minimum_image_ok(ortho, 0.5));
  EXPECT_FALSE(minimum_image_ok(ortho, 0.6));
}

TEST(Box, TriclinicSixtyDegrees) {
  // a and b at 60 degrees (hexagonal), c normal: volume sqrt(3)/2.
  const Box hex = make_box({{{1, 0, 0}, {0.5, s3 / 2, 0}, {0, 0, 1}}});
  EXPECT_NEAR(face_width(hex, 0), s3 / 2, 1e-15);
  EXPECT_NEAR(face_width(hex, 1), s3 / 2, 1e-15);
  EXPECT_NEAR(face_width(hex, 2), 1, 1e-15);
  EXPECT_EQ(image_range(hex, 0.9), (std::array<int, 3>{2, 2, 1}));
  // A rhombohedral cell, all angles 60 degrees (fcc primitive): widths sqrt(2/3) |a|.
  const double h = 1 / std::sqrt(2.0);
  const Box fcc = make_box({{{0, h, h}, {h, 0, h}, {h, h, 0}}});
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(face_width(fcc, k), std::sqrt(2.0 / 3.0), 1e-15);
}

TEST(Box, VerySkewedCell) {
  // b leans 1000 a-lengths along a: width along a is 1 / |b x c| = 1 / sqrt(1 + 1e6).
  const Box skew = make_box({{{1, 0, 0}, {1000, 1, 0}, {0, 0, 1}}});
  EXPECT_NEAR(face_width(skew, 0), 1 / std::sqrt(1 + 1e6), 1e-18);
  EXPECT_NEAR(face_width(skew, 1), 1, 1e-12);
  EXPECT_NEAR(face_width(skew, 2), 1, 1e-12);
  EXPECT_EQ(image_range(skew, 1)[0], 1001);
  EXPECT_FALSE(minimum_image_ok(skew, 0.01));
}

TEST(Box, LeftHandedCell) {
  // b along z, c along y: det = -24.
  const Box left = make_box({{{2, 0, 0}, {0, 0, 3}, {0, 4, 0}}});
  validate(left);
  EXPECT_DOUBLE_EQ(face_width(left, 0), 2);
  EXPECT_DOUBLE_EQ(face_width(left, 1), 3);
  EXPECT_DOUBLE_EQ(face_width(left, 2), 4);
  const Box hex_left = make_box({{{1, 0, 0}, {0.5, -s3 / 2, 0}, {0, 0, 1}}});
  EXPECT_NEAR(face_width(hex_left, 0), s3 / 2, 1e-15);
  EXPECT_NEAR(face_width(hex_left, 2), 1, 1e-15);
}

TEST(Box, SlabsAndWires) {
  // Slab: a, b periodic in the xy plane, c zero. Width along a within the plane:
  // |a x b| / |b| = 6 / sqrt(10); along b: 6 / |a| = 3.
  const Box slab = make_box({{{2, 0, 0}, {1, 3, 0}, {0, 0, 0}}}, {true, true, false});
  EXPECT_NEAR(face_width(slab, 0), 6 / std::sqrt(10.0), 1e-15);
  EXPECT_NEAR(face_width(slab, 1), 3, 1e-15);
  EXPECT_EQ(face_width(slab, 2), inf);
  EXPECT_EQ(image_range(slab, 3.5), (std::array<int, 3>{2, 2, 0}));
  // The non-periodic row does not matter, even parallel to a periodic one.
  const Box slab_c = make_box({{{2, 0, 0}, {1, 3, 0}, {5, 0, 0}}}, {true, true, false});
  EXPECT_DOUBLE_EQ(face_width(slab_c, 0), face_width(slab, 0));
  const Box slab_tilted = make_box({{{2, 0, 0}, {1, 3, 0}, {7, 7, 1}}}, {true, true, false});
  EXPECT_DOUBLE_EQ(face_width(slab_tilted, 1), face_width(slab, 1));
  // Wire along (3, 4, 0), length 5; the other rows zero.
  const Box wire = make_box({{{0, 0, 0}, {0, 0, 0}, {3, 4, 0}}}, {false, false, true});
  EXPECT_EQ(face_width(wire, 0), inf);
  EXPECT_NEAR(face_width(wire, 2), 5, 1e-15);
  EXPECT_EQ(image_range(wire, 11), (std::array<int, 3>{0, 0, 3}));
  EXPECT_TRUE(minimum_image_ok(wire, 2.5));
  EXPECT_FALSE(minimum_image_ok(wire, 2.6));
}

TEST(Box, ScaleDoesNotMatter) {
  for (double scale : {1e-300, 1e-150, 1e-20, 1.0, 1e20, 1e150, 1e300}) {
    const Box hex = make_box({{{scale, 0, 0}, {0.5 * scale, s3 / 2 * scale, 0}, {0, 0, scale}}});
    EXPECT_NEAR(face_width(hex, 0) / scale, s3 / 2, 1e-14) << scale;
    EXPECT_NEAR(face_width(hex, 2) / scale, 1, 1e-14) << scale;
  }
}

TEST(Box, SingularCellsAreRefused) {
  // Two parallel periodic rows.
  std::string message = refused([] { validate(make_box({{{1, 0, 0}, {2, 0, 0}, {0, 0, 1}}})); });
  EXPECT_TRUE(contains(message, "linearly dependent")) << message;
  EXPECT_TRUE(contains(message, "singular")) << message;
  EXPECT_TRUE(contains(message, "b = (2, 0, 0)")) << message;
  // Coplanar rows.
  message = refused([] { validate(make_box({{{1, 0, 0}, {0, 1, 0}, {1, 1, 0}}})); });
  EXPECT_TRUE(contains(message, "singular")) << message;
  // Nearly parallel: 1e-7 rad refused, 1e-5 rad accepted.
  message = refused([] { validate(make_box({{{1, 0, 0}, {1, 1e-7, 0}, {0, 0, 1}}})); });
  EXPECT_TRUE(contains(message, "below 1e-6")) << message;
  validate(make_box({{{1, 0, 0}, {1, 1e-5, 0}, {0, 0, 1}}}));
  // A zero periodic row names the row.
  message = refused([] { validate(make_box({{{1, 0, 0}, {0, 0, 0}, {0, 0, 1}}})); });
  EXPECT_TRUE(contains(message, "lattice vector b has zero length")) << message;
  message = refused([] { face_width(Box::orthorhombic(1, 1, 0), 0); });
  EXPECT_TRUE(contains(message, "c has zero length")) << message;
  // Slab with parallel periodic rows.
  message = refused([] {
    validate(make_box({{{1, 1, 0}, {-3, -3, 0}, {0, 0, 0}}}, {true, true, false}));
  });
  EXPECT_TRUE(contains(message, "singular")) << message;
  // Non-finite entries, periodic row or not.
  for (double bad : {std::nan(""), inf, -inf}) {
    message = refused([&] { validate(make_box({{{1, 0, 0}, {0, 1, 0}, {0, bad, 1}}})); });
    EXPECT_TRUE(contains(message, "non-finite")) << message;
    EXPECT_TRUE(contains(message, "row c")) << message;
    message = refused([&] {
      validate(make_box({{{bad, 0, 0}, {0, 1, 0}, {0, 0, 1}}}, {false, true, true}));
    });
    EXPECT_TRUE(contains(message, "row a")) << message;
  }
  // Every helper validates.
  const Box singular = make_box({{{1, 0, 0}, {2, 0, 0}, {0, 0, 1}}});
  refused([&] { image_range(singular, 1); });
  refused([&] { minimum_image_ok(singular, 1); });
  refused([&] { wrap(singular, {0, 0, 0}); });
}

TEST(Box, BadArgumentsAreRefused) {
  const Box cube = Box::orthorhombic(1, 1, 1);
  for (double cutoff : {0.0, -1.0, std::nan(""), inf}) {
    EXPECT_TRUE(contains(refused([&] { image_range(cube, cutoff); }), "cutoff")) << cutoff;
    refused([&] { minimum_image_ok(cube, cutoff); });
  }
  refused([&] { face_width(cube, 3); });
  refused([&] { face_width(cube, -1); });
  EXPECT_TRUE(
      contains(refused([&] { image_range(Box::orthorhombic(1e-300, 1, 1), 1); }), "too thin"));
  refused([&] { wrap(cube, {std::nan(""), 0, 0}); });
  EXPECT_TRUE(contains(refused([&] { wrap(cube, {1e10, 0, 0}); }), "int32"));
  EXPECT_EQ(wrap(cube, {-2147483648.0, 0, 0}).shift[0], -2147483647 - 1);
}

std::array<double, 3> combine(const Box& box, const std::array<double, 3>& f) {
  std::array<double, 3> x{0, 0, 0};
  for (int k = 0; k < 3; ++k)
    for (int c = 0; c < 3; ++c) x[c] += f[k] * box.cell[k][c];
  return x;
}

// Fractional coordinates of x in a fully periodic box (Cramer's rule, independent of box.cpp).
std::array<double, 3> fractional(const Box& box, const std::array<double, 3>& x) {
  const auto& m = box.cell;
  auto det3 = [](const std::array<double, 3>& r0, const std::array<double, 3>& r1,
                 const std::array<double, 3>& r2) {
    return r0[0] * (r1[1] * r2[2] - r1[2] * r2[1]) - r0[1] * (r1[0] * r2[2] - r1[2] * r2[0]) +
           r0[2] * (r1[0] * r2[1] - r1[1] * r2[0]);
  };
  std::array<std::array<double, 3>, 3> rows;
  for (int r = 0; r < 3; ++r) rows[r] = {m[r][0], m[r][1], m[r][2]};
  const double det = det3(rows[0], rows[1], rows[2]);
  std::array<double, 3> f{};
  for (int k = 0; k < 3; ++k) {
    auto replaced = rows;
    replaced[k] = x;
    f[k] = det3(replaced[0], replaced[1], replaced[2]) / det;
  }
  return f;
}

std::vector<Box> full_boxes() {
  return {Box::orthorhombic(2, 2, 2),
          Box::orthorhombic(1, 2, 3),
          make_box({{{1, 0, 0}, {0.5, s3 / 2, 0}, {0, 0, 1}}}),
          make_box({{{1, 0, 0}, {1000, 1, 0}, {0, 0, 1}}}),
          make_box({{{2, 0, 0}, {0, 0, 3}, {0, 4, 0}}}),
          make_box({{{3.1, 0.2, -0.4}, {1.3, 2.7, 0.1}, {-0.9, 1.1, 2.3}}})};
}

TEST(Box, WrapRoundTripsFarFromTheCell) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<double> unit(1e-6, 1 - 1e-6);
  std::uniform_int_distribution<int> boxes(-1000, 1000);
  for (const Box& box : full_boxes()) {
    for (int trial = 0; trial < 500; ++trial) {
      const std::array<double, 3> f{unit(rng), unit(rng), unit(rng)};
      const std::array<int, 3> n{boxes(rng), boxes(rng), boxes(rng)};
      const std::array<double, 3> inside = combine(box, f);
      const std::array<double, 3> x = combine(box, {f[0] + n[0], f[1] + n[1], f[2] + n[2]});
      const Wrapped w = wrap(box, x);
      ASSERT_EQ(w.shift, (std::array<std::int32_t, 3>{n[0], n[1], n[2]}))
          << "trial " << trial << " f " << f[0] << " " << f[1] << " " << f[2];
      // x = wrapped + shift . cell, and wrapped is the point inside.
      const std::array<double, 3> back =
          combine(box, {double(w.shift[0]), double(w.shift[1]), double(w.shift[2])});
      double scale = 0;
      for (int k = 0; k < 3; ++k)
        for (int c = 0; c < 3; ++c) scale = std::max(scale, std::abs(box.cell[k][c]));
      for (int c = 0; c < 3; ++c) {
        EXPECT_NEAR(w.x[c] + back[c], x[c], 1e-9 * scale * 1000);
        EXPECT_NEAR(w.x[c], inside[c], 1e-9 * scale * 1000);
      }
      const std::array<double, 3> g = fractional(box, w.x);
      for (int k = 0; k < 3; ++k) {
        EXPECT_GE(g[k], -1e-9);
        EXPECT_LT(g[k], 1 + 1e-9);
      }
    }
  }
}

TEST(Box, WrapAtTheFaces) {
  const Box cube = Box::orthorhombic(2, 2, 2);
  EXPECT_EQ(wrap(cube, {0, 0, 0}).shift, (std::array<std::int32_t, 3>{0, 0, 0}));
  EXPECT_EQ(wrap(cube, {2, 4, -2}).shift, (std::array<std::int32_t, 3>{1, 2, -1}));
  EXPECT_EQ(wrap(cube, {2, 4, -2}).x, (std::array<double, 3>{0, 0, 0}));
  // A tiny negative coordinate: f + 1 rounds to 1, so it stays in this cell (frac 0, not 1).
  const Wrapped tiny = wrap(cube, {-1e-20, 0, 0});
  EXPECT_EQ(tiny.shift[0], 0);
  EXPECT_EQ(tiny.x[0], -1e-20);
  const Wrapped below = wrap(cube, {-0.5, 0, 0});
  EXPECT_EQ(below.shift[0], -1);
  EXPECT_EQ(below.x[0], 1.5);
}

TEST(Box, WrapLeavesOpenAxesAlone) {
  const Box slab = make_box({{{2, 0, 0}, {1, 3, 0}, {0, 0, 0}}}, {true, true, false});
  const Wrapped w = wrap(slab, {2 * 7 + 1 * -3 + 0.5, 3 * -3 + 1, 123.25});
  EXPECT_EQ(w.shift, (std::array<std::int32_t, 3>{7, -3, 0}));
  EXPECT_NEAR(w.x[0], 0.5, 1e-12);
  EXPECT_NEAR(w.x[1], 1, 1e-12);
  EXPECT_EQ(w.x[2], 123.25);
  // A wire along z: only z wraps, whatever x and y.
  const Box wire = Box::orthorhombic(0, 0, 5, false, false, true);
  const Wrapped v = wrap(wire, {1e6, -1e6, -12});
  EXPECT_EQ(v.shift, (std::array<std::int32_t, 3>{0, 0, -3}));
  EXPECT_EQ(v.x, (std::array<double, 3>{1e6, -1e6, 3}));
}

// image_range's promise, by brute force: among wrapped positions, every image within the cutoff
// has |S_k| <= m_k (searched over a much wider range).
TEST(Box, ImageRangeFindsEveryPair) {
  std::mt19937_64 rng(3);
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<Box> boxes = full_boxes();
  boxes.push_back(make_box({{{2, 0, 0}, {1, 3, 0}, {0, 0, 0}}}, {true, true, false}));
  boxes.push_back(make_box({{{0.3, 0.1, 0}, {0, 0.5, 0.2}, {0.1, 0, 0.4}}}));
  for (const Box& box : boxes) {
    for (double cutoff : {0.3, 1.0, 2.7}) {
      const std::array<int, 3> m = image_range(box, cutoff);
      if (m[0] > 50 || m[1] > 50) continue;  // the skewed cell at a large cutoff: too slow
      for (int trial = 0; trial < 40; ++trial) {
        // Two wrapped points (fractional coordinates in [0, 1); z free on an open axis).
        std::array<double, 3> fi{unit(rng), unit(rng), unit(rng)};
        std::array<double, 3> fj{unit(rng), unit(rng), unit(rng)};
        std::array<double, 3> d{};
        const std::array<double, 3> xi = combine(box, fi), xj = combine(box, fj);
        for (int c = 0; c < 3; ++c) d[c] = xj[c] - xi[c];
        std::array<int, 3> wide{};
        for (int k = 0; k < 3; ++k) wide[k] = box.pbc[k] ? m[k] + 3 : 0;
        for (int s0 = -wide[0]; s0 <= wide[0]; ++s0)
          for (int s1 = -wide[1]; s1 <= wide[1]; ++s1)
            for (int s2 = -wide[2]; s2 <= wide[2]; ++s2) {
              const std::array<double, 3> shift =
                  combine(box, {double(s0), double(s1), double(s2)});
              double r2 = 0;
              for (int c = 0; c < 3; ++c) r2 += (d[c] + shift[c]) * (d[c] + shift[c]);
              if (r2 < cutoff * cutoff) {
                ASSERT_LE(std::abs(s0), m[0]);
                ASSERT_LE(std::abs(s1), m[1]);
                ASSERT_LE(std::abs(s2), m[2]);
              }
            }
      }
    }
  }
}

}  // namespace
}  // namespace raycut
