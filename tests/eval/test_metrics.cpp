// Metric tests: hand-computed IoU / accuracy / boundary IoU cases (shifted squares, empty masks, masks
// touching the border, several d), and the fast erosion against a naive iterated 3x3 erosion.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/error.h"
#include "eval/metrics.h"
#include "eval_test_util.h"

using namespace hgs::eval;
using hgs::eval::test::ascii;

TEST(EvalMetrics, ShiftedSquaresHandComputed) {
  // G: 3x3 square at x 1..3; P: the same shifted right by one. 5x5 image, d = 1.
  Mask g = ascii({".....", ".###.", ".###.", ".###.", "....."});
  Mask p = ascii({".....", "..###", "..###", "..###", "....."});
  EXPECT_DOUBLE_EQ(iou(g, p, 5, 5), 6.0 / 12.0);
  EXPECT_DOUBLE_EQ(pixel_accuracy(g, p, 5, 5), 19.0 / 25.0);
  // B(G) = square minus its centre (2,2); B(P) = square minus (3,2). Common: (2,1), (3,1), (2,3), (3,3).
  EXPECT_EQ(boundary_region(g, 5, 5, 1), ascii({".....", ".###.", ".#.#.", ".###.", "....."}));
  EXPECT_DOUBLE_EQ(boundary_iou(g, p, 5, 5, 1), 4.0 / 12.0);
  EXPECT_DOUBLE_EQ(boundary_iou(g, g, 5, 5, 1), 1.0);
  // Both boundaries empty: NaN as the reference's 0 / 0 (skipped by the report's means); one empty: 0.
  const Mask empty(25, 0);
  EXPECT_TRUE(std::isnan(boundary_iou(empty, empty, 5, 5, 1)));
  EXPECT_DOUBLE_EQ(boundary_iou(g, empty, 5, 5, 1), 0.0);
  // d = 2 erodes the whole 3x3 square: boundaries are the squares, BIoU = IoU.
  EXPECT_DOUBLE_EQ(boundary_iou(g, p, 5, 5, 2), 6.0 / 12.0);
  Confusion c = confusion(g, p, 5, 5);
  EXPECT_EQ(c.tp, 6);
  EXPECT_EQ(c.fp, 3);
  EXPECT_EQ(c.fn, 3);
  EXPECT_EQ(c.tn, 13);
}

TEST(EvalMetrics, MaskTouchingTheBorderErodesFromTheBorder) {
  // 4x4 all-inside ground truth: zero padding makes its outer ring the boundary for d = 1.
  Mask g(16, 1);
  Mask p = ascii({"##..", "##..", "##..", "##.."});
  EXPECT_EQ(boundary_region(g, 4, 4, 1), ascii({"####", "#..#", "#..#", "####"}));
  EXPECT_EQ(boundary_region(p, 4, 4, 1), p);  // 2 wide: nothing survives the erosion
  // d = 1: B(G) 12 px, B(P) 8 px, common 6 px (column 0 and (1,0), (1,3)).
  EXPECT_DOUBLE_EQ(boundary_iou(g, p, 4, 4, 1), 6.0 / 14.0);
  // d = 2: B(G) is all 16 px.
  EXPECT_DOUBLE_EQ(boundary_iou(g, p, 4, 4, 2), 8.0 / 16.0);
  EXPECT_DOUBLE_EQ(iou(g, p, 4, 4), 0.5);
  EXPECT_DOUBLE_EQ(pixel_accuracy(g, p, 4, 4), 0.5);
}

TEST(EvalMetrics, LargerDOnALargerSquare) {
  // 9x9 square inside an 11x11 image: d = 1 -> ring of 32 px, d = 2 -> 81 - 25 = 56, d = 3 -> 81 - 9 = 72.
  Mask g(121, 0);
  for (int y = 1; y <= 9; ++y)
    for (int x = 1; x <= 9; ++x) g[y * 11 + x] = 1;
  auto count = [](const Mask& m) {
    long n = 0;
    for (auto v : m) n += v != 0;
    return n;
  };
  EXPECT_EQ(count(boundary_region(g, 11, 11, 1)), 32);
  EXPECT_EQ(count(boundary_region(g, 11, 11, 2)), 56);
  EXPECT_EQ(count(boundary_region(g, 11, 11, 3)), 72);
  EXPECT_EQ(count(boundary_region(g, 11, 11, 5)), 81);
  // P = the inner 7x7 square: with d = 1, B(P) is its 24-px ring which is the second ring of G -> disjoint.
  Mask p(121, 0);
  for (int y = 2; y <= 8; ++y)
    for (int x = 2; x <= 8; ++x) p[y * 11 + x] = 1;
  EXPECT_DOUBLE_EQ(boundary_iou(g, p, 11, 11, 1), 0.0);
  // d = 2: B(G) = rings 1-2 (56 px), B(P) = rings 2-3 (24 + 16 = 40 px), common ring 2 (24 px).
  EXPECT_DOUBLE_EQ(boundary_iou(g, p, 11, 11, 2), 24.0 / 72.0);
}

TEST(EvalMetrics, EmptyMaskConventions) {
  Mask e(12, 0), f(12, 0);
  f[5] = 1;
  EXPECT_DOUBLE_EQ(iou(e, e, 4, 3), 1.0);
  EXPECT_TRUE(std::isnan(boundary_iou(e, e, 4, 3)));  // the reference's 0 / 0
  EXPECT_DOUBLE_EQ(pixel_accuracy(e, e, 4, 3), 1.0);
  EXPECT_DOUBLE_EQ(iou(e, f, 4, 3), 0.0);
  EXPECT_DOUBLE_EQ(iou(f, e, 4, 3), 0.0);
  EXPECT_DOUBLE_EQ(boundary_iou(f, e, 4, 3), 0.0);
  EXPECT_DOUBLE_EQ(pixel_accuracy(f, e, 4, 3), 11.0 / 12.0);
  MaskScores s = score_mask(f, f, 4, 3);
  EXPECT_DOUBLE_EQ(s.iou, 1.0);
  EXPECT_DOUBLE_EQ(s.biou, 1.0);
  EXPECT_DOUBLE_EQ(s.acc, 1.0);
  // Any non-zero value is inside.
  Mask g(12, 0);
  g[5] = 255;
  EXPECT_DOUBLE_EQ(iou(g, f, 4, 3), 1.0);
}

TEST(EvalMetrics, BoundaryWidthFollowsChengEtAl) {
  EXPECT_EQ(boundary_width(320, 240), 8);     // 0.02 * 400
  EXPECT_EQ(boundary_width(96, 72), 2);       // 0.02 * 120 = 2.4
  EXPECT_EQ(boundary_width(1440, 1080), 36);  // 0.02 * 1800
  EXPECT_EQ(boundary_width(10, 10), 1);       // 0.28 -> 0 -> at least 1
  EXPECT_EQ(boundary_width(100, 75), 2);      // 0.02 * 125 = 2.5 -> 2 (half to even, as Python)
  EXPECT_EQ(boundary_width(175, 0 + 1), 4);   // 0.02 * 175.003 = 3.5001 -> 4
}

TEST(EvalMetrics, FastErosionMatchesNaiveIteratedErosion) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    const int w = 5 + trial % 13, h = 4 + (trial * 7) % 11;
    Mask m(size_t(w) * h);
    // Blobby masks: threshold a sum of a few discs so that erosions are not trivially empty.
    std::uniform_int_distribution<int> ux(0, w - 1), uy(0, h - 1), ur(1, 5);
    for (int k = 0; k < 3; ++k) {
      int cx = ux(rng), cy = uy(rng), r = ur(rng);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x)
          if ((x - cx) * (x - cx) + (y - cy) * (y - cy) <= r * r) m[size_t(y) * w + x] = 1;
    }
    for (int d = 0; d <= 4; ++d) {
      // Reference: d iterations of a plain 3x3 erosion with zeros outside.
      Mask ref = m;
      for (int it = 0; it < d; ++it) ref = hgs::eval::test::naive_erode_zero_pad(ref, w, h, 1);
      ASSERT_EQ(erode3x3(m, w, h, d, 0), ref) << "trial " << trial << " d " << d;
      // Outside = 1: pad with ones, erode, crop.
      Mask big(size_t(w + 2 * d) * (h + 2 * d), 1);
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) big[size_t(y + d) * (w + 2 * d) + x + d] = m[size_t(y) * w + x];
      Mask eb = hgs::eval::test::naive_erode_zero_pad(big, w + 2 * d, h + 2 * d, 0);
      for (int it = 0; it < d; ++it) {
        // Erode with "outside = 1" semantics inside the padded frame: the frame itself stays 1.
        Mask nb = eb;
        for (int y = 0; y < h + 2 * d; ++y)
          for (int x = 0; x < w + 2 * d; ++x) {
            bool ok = true;
            for (int dy = -1; dy <= 1; ++dy)
              for (int dx = -1; dx <= 1; ++dx) {
                int xx = x + dx, yy = y + dy;
                if (xx >= 0 && yy >= 0 && xx < w + 2 * d && yy < h + 2 * d)
                  ok = ok && eb[size_t(yy) * (w + 2 * d) + xx];
              }
            nb[size_t(y) * (w + 2 * d) + x] = ok;
          }
        eb = nb;
      }
      Mask crop(m.size());
      for (int y = 0; y < h; ++y)
        for (int x = 0; x < w; ++x) crop[size_t(y) * w + x] = eb[size_t(y + d) * (w + 2 * d) + x + d];
      ASSERT_EQ(erode3x3(m, w, h, d, 1), crop) << "outside=1 trial " << trial << " d " << d;
    }
  }
}

TEST(EvalMetrics, SizeMismatchIsAnError) {
  Mask a(12, 0), b(11, 0);
  EXPECT_THROW(iou(a, b, 4, 3), hgs::Error);
  EXPECT_THROW(boundary_iou(a, a, 3, 3), hgs::Error);
  EXPECT_THROW(pixel_accuracy(a, a, 0, 0), hgs::Error);
}
