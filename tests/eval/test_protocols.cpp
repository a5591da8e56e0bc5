// LERF-OVS post-processing and localisation on synthetic relevancy maps (hand-derived masks and an
// independent reference pipeline) and the 3D-OVS protocol on a toy case.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <tuple>

#include "core/error.h"
#include "eval/protocols.h"
#include "eval_test_util.h"

using namespace hgs::eval;

namespace {

// 60x40 map: 1 on the 20x20 square x 20..39, y 10..29, 0 elsewhere.
std::vector<float> square_map(int w = 60, int h = 40) {
  std::vector<float> v(size_t(w) * h, 0.f);
  for (int y = 10; y < 30; ++y)
    for (int x = 20; x < 40; ++x) v[size_t(y) * w + x] = 1.f;
  return v;
}

Mask square_mask(int w = 60, int h = 40) {
  Mask m(size_t(w) * h, 0);
  for (int y = 10; y < 30; ++y)
    for (int x = 20; x < 40; ++x) m[size_t(y) * w + x] = 1;
  return m;
}

}  // namespace

TEST(EvalLerfProtocol, SquareMapHandDerived) {
  // v' = 0.5 (box + v): inside the square >= 0.5 + 0.5 * 100/900, outside <= 0.5 * 400/900; max at the centre
  // plateau 0.5 (1 + 400/900). So n > 0.7 (out > 0.4) exactly on the square.
  LerfOptions noMaj;
  noMaj.majority = 1;
  LerfPost P = lerf_postprocess(square_map(), 60, 40, noMaj);
  EXPECT_EQ(P.raw_mask, square_mask());
  EXPECT_EQ(P.mask, square_mask());
  EXPECT_NEAR(*std::max_element(P.smoothed.begin(), P.smoothed.end()), 0.5 * (1 + 400.0 / 900.0), 1e-6);
  EXPECT_NEAR(*std::max_element(P.activation.begin(), P.activation.end()), 1.0, 1e-6);
  EXPECT_EQ(*std::min_element(P.activation.begin(), P.activation.end()), 0.f);
  // The 7x7 majority filter removes 5 pixels at each corner of the square: (0,0), (1,0), (2,0), (0,1), (0,2)
  // relative to the corner have 16, 20, 24, 20, 24 of 49 window pixels inside.
  LerfPost Q = lerf_postprocess(square_map(), 60, 40);
  Mask expect = square_mask();
  for (int cy : {0, 1})
    for (int cx : {0, 1})
      for (auto [dx, dy] : {std::pair{0, 0}, {1, 0}, {2, 0}, {0, 1}, {0, 2}}) {
        const int x = cx ? 39 - dx : 20 + dx, y = cy ? 29 - dy : 10 + dy;
        expect[size_t(y) * 60 + x] = 0;
      }
  EXPECT_EQ(Q.mask, expect);
  LerfCategory gt;
  gt.name = "square";
  gt.mask = square_mask();
  gt.bboxes = {{20, 10, 40, 30}};
  LerfQueryResult R = evaluate_lerf_query(square_map(), 60, 40, gt);
  EXPECT_DOUBLE_EQ(R.scores.iou, 380.0 / 400.0);
  EXPECT_DOUBLE_EQ(R.scores.acc, 1.0 - 20.0 / 2400.0);
  EXPECT_TRUE(R.loc.hit);
  // The box-filter plateau (the window holds the whole square) is x 25..35, y 15..25; first in raster order.
  EXPECT_EQ(R.loc.x, 25);
  EXPECT_EQ(R.loc.y, 15);
  EXPECT_NEAR(R.loc.score, 400.0 / 900.0, 1e-6);
}

TEST(EvalLerfProtocol, LocalisationBoxes) {
  LerfPost P = lerf_postprocess(square_map(), 60, 40);
  EXPECT_FALSE(lerf_localise(P.boxed, 60, 40, {{0, 0, 10, 10}}).hit);
  EXPECT_FALSE(lerf_localise(P.boxed, 60, 40, {}).hit);
  // A box covering only the last tied maximum (35, 25): centre (35.5, 25.5).
  Localisation L = lerf_localise(P.boxed, 60, 40, {{0, 0, 5, 5}, {35, 25, 36, 26}});
  EXPECT_TRUE(L.hit);
  EXPECT_EQ(L.x, 35);
  EXPECT_EQ(L.y, 25);
  // Just outside the plateau: (36, 26) has a smaller filtered value.
  EXPECT_FALSE(lerf_localise(P.boxed, 60, 40, {{36, 26, 40, 30}}).hit);
}

TEST(EvalLerfProtocol, MatchesIndependentReference) {
  std::mt19937 rng(9);
  std::normal_distribution<float> nd(0.f, 0.1f);
  const int w = 71, h = 53;
  std::vector<float> v(size_t(w) * h);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      v[size_t(y) * w + x] =
          0.5f + 0.4f * std::exp(-((x - 40.f) * (x - 40.f) + (y - 20.f) * (y - 20.f)) / 150.f) + nd(rng);
  LerfPost P = lerf_postprocess(v, w, h);
  // Reference: brute-force box filter, the formulas in double, brute-force majority filter.
  auto box = hgs::eval::test::brute_box(v, w, h, 30);
  std::vector<double> s(v.size());
  for (size_t i = 0; i < v.size(); ++i) s[i] = 0.5 * (double(box[i]) + v[i]);
  const double lo = *std::min_element(s.begin(), s.end()), hi = *std::max_element(s.begin(), s.end());
  Mask raw(v.size());
  int borderline = 0;
  for (size_t i = 0; i < v.size(); ++i) {
    const double out = std::clamp(2 * (s[i] - lo) / (hi - lo + 1e-9) - 1, 0.0, 1.0);
    raw[i] = out > 0.4;
    ASSERT_NEAR(P.activation[i], out, 1e-5);
    borderline += std::abs(out - 0.4) < 1e-5;
  }
  ASSERT_EQ(borderline, 0) << "test map has values at the threshold; pick another seed";
  EXPECT_EQ(P.raw_mask, raw);
  EXPECT_EQ(P.mask, hgs::eval::test::brute_majority(raw, w, h, 7));
  long n = 0;
  for (auto m : P.mask) n += m;
  EXPECT_GT(n, 20);  // the blob is found
  EXPECT_LT(n, long(v.size()) / 2);
}

TEST(EvalLerfProtocol, ConstantMapGivesEmptyMaskAndBadInputFails) {
  std::vector<float> c(30 * 20, 0.7f);
  LerfPost P = lerf_postprocess(c, 30, 20);
  EXPECT_EQ(P.mask, Mask(600, 0));
  std::vector<float> bad(600, 0.f);
  bad[17] = std::nanf("");
  EXPECT_THROW(lerf_postprocess(bad, 30, 20), hgs::Error);
  EXPECT_THROW(lerf_postprocess(c, 30, 21), hgs::Error);
}

TEST(Eval3dOvsProtocol, TwoClassToyCaseWithAbsentClass) {
  // 4x2 image, classes 0 and 1 present, class 2 absent from both; pixel 7 unlabelled, pixel 5 mislabelled.
  std::vector<std::vector<float>> rel = {{0.9f, 0.8f, 0.2f, 0.1f, 0.9f, 0.6f, 0.3f, 0.1f},
                                         {0.1f, 0.3f, 0.7f, 0.9f, 0.2f, 0.5f, 0.8f, 0.9f},
                                         std::vector<float>(8, 0.f)};
  std::vector<Mask> gt = {{1, 1, 0, 0, 1, 0, 0, 0}, {0, 0, 1, 1, 0, 1, 1, 0}, Mask(8, 0)};
  OvsImageResult R = evaluate_3dovs_image(rel, gt, 4, 2);
  EXPECT_EQ(R.prediction, (std::vector<uint16_t>{0, 0, 1, 1, 0, 0, 1, 1}));
  ASSERT_EQ(R.iou.size(), 3u);
  EXPECT_DOUBLE_EQ(R.iou[0], 3.0 / 4.0);
  EXPECT_DOUBLE_EQ(R.iou[1], 3.0 / 5.0);
  EXPECT_DOUBLE_EQ(R.iou[2], 0.0);  // absent in both scores 0 (basic iou() would say 1)
  EXPECT_DOUBLE_EQ(R.miou, (0.75 + 0.6 + 0.0) / 3.0);
  EXPECT_DOUBLE_EQ(R.accuracy, 6.0 / 8.0);  // pixel 5 (wrong class) and 7 (unlabelled) are errors
  // On a 2-row image every inside pixel is boundary (d = 1), so BIoU = IoU per class.
  EXPECT_DOUBLE_EQ(R.biou[0], 0.75);
  EXPECT_DOUBLE_EQ(R.biou[1], 0.6);
  EXPECT_DOUBLE_EQ(R.biou[2], 0.0);
  EXPECT_DOUBLE_EQ(R.mbiou, R.miou);
  // Two classes only: the absent class is no longer averaged in.
  OvsImageResult R2 = evaluate_3dovs_image({rel[0], rel[1]}, {gt[0], gt[1]}, 4, 2);
  EXPECT_DOUBLE_EQ(R2.miou, (0.75 + 0.6) / 2.0);
  // A pixel in two class masks is an error even when the prediction is one of them.
  std::vector<Mask> gt2 = {{1, 1, 0, 0, 1, 0, 0, 0}, {1, 0, 1, 1, 0, 1, 1, 1}};
  EXPECT_DOUBLE_EQ(evaluate_3dovs_image({rel[0], rel[1]}, gt2, 4, 2).accuracy, 6.0 / 8.0);
}

TEST(Eval3dOvsProtocol, ArgmaxTiesGoToTheLowerClassAndSizesAreChecked) {
  std::vector<std::vector<float>> rel = {{0.5f, 0.2f}, {0.5f, 0.7f}, {0.1f, 0.7f}};
  EXPECT_EQ(argmax_classes(rel, 2, 1), (std::vector<uint16_t>{0, 1}));
  EXPECT_THROW(argmax_classes({}, 2, 1), hgs::Error);
  EXPECT_THROW(argmax_classes({{0.f}}, 2, 1), hgs::Error);
  EXPECT_THROW(evaluate_3dovs_image(rel, {Mask(2, 0)}, 2, 1), hgs::Error);
}

TEST(Eval3dOvsProtocol, LabelledOnlyScoringLeavesOutUnlabelledPixelsAndClassesNotInView) {
  // The toy case above: pixel 7 is unlabelled (predicted 1), class 2 is in no mask.
  std::vector<std::vector<float>> rel = {{0.9f, 0.8f, 0.2f, 0.1f, 0.9f, 0.6f, 0.3f, 0.1f},
                                         {0.1f, 0.3f, 0.7f, 0.9f, 0.2f, 0.5f, 0.8f, 0.9f},
                                         std::vector<float>(8, 0.f)};
  std::vector<Mask> gt = {{1, 1, 0, 0, 1, 0, 0, 0}, {0, 0, 1, 1, 0, 1, 1, 0}, Mask(8, 0)};
  const OvsImageResult R = evaluate_3dovs_image(rel, gt, 4, 2, 0, OvsScoring::LabelledOnly);
  EXPECT_EQ(R.prediction, (std::vector<uint16_t>{0, 0, 1, 1, 0, 0, 1, 1}));
  EXPECT_DOUBLE_EQ(R.iou[0], 3.0 / 4.0);  // pixel 5 still counts against class 0 and for class 1's miss
  EXPECT_DOUBLE_EQ(R.iou[1], 3.0 / 4.0);  // pixel 7 (unlabelled) is no longer a false positive
  EXPECT_TRUE(std::isnan(R.iou[2]));      // not in view: not scored
  EXPECT_TRUE(std::isnan(R.biou[2]));
  EXPECT_DOUBLE_EQ(R.miou, 0.75);
  EXPECT_DOUBLE_EQ(R.accuracy, 6.0 / 7.0);  // over the 7 labelled pixels
  EXPECT_DOUBLE_EQ(R.ceiling, 1.0);
  // A class predicted where it is not in view still costs the class whose pixels it takes.
  std::vector<std::vector<float>> rel2 = rel;
  rel2[2][0] = 2.f;
  const OvsImageResult R2 = evaluate_3dovs_image(rel2, gt, 4, 2, 0, OvsScoring::LabelledOnly);
  EXPECT_DOUBLE_EQ(R2.iou[0], 2.0 / 4.0);
  EXPECT_TRUE(std::isnan(R2.iou[2]));
  // On a frame whose classes cover every pixel and are all in view the two scorings agree.
  std::vector<Mask> full = {{1, 1, 0, 0, 1, 0, 0, 0}, {0, 0, 1, 1, 0, 1, 1, 1}};
  const OvsImageResult P = evaluate_3dovs_image({rel[0], rel[1]}, full, 4, 2);
  const OvsImageResult L = evaluate_3dovs_image({rel[0], rel[1]}, full, 4, 2, 0, OvsScoring::LabelledOnly);
  EXPECT_EQ(P.iou, L.iou);
  EXPECT_EQ(P.biou, L.biou);
  EXPECT_DOUBLE_EQ(P.accuracy, L.accuracy);
}

TEST(Eval3dOvsProtocol, CeilingIsTheBestAnyArgmaxPredictionScoresByBruteForce) {
  // Every prediction of C classes on a W x H frame (C^(W H) of them) against random disjoint class masks with
  // unlabelled pixels and, in some frames, classes not in view: the best protocol mIoU equals ovs_ceiling.
  std::mt19937 rng(7);
  const int W = 3, H = 2, n = W * H;
  for (int C : {2, 3}) {
    for (int trial = 0; trial < 40; ++trial) {
      std::vector<Mask> gt(C, Mask(n, 0));
      std::uniform_int_distribution<int> pick(-1, C - 1);  // -1: unlabelled
      for (int i = 0; i < n; ++i)
        if (const int c = pick(rng); c >= 0) gt[c][i] = 1;
      size_t total = 1;
      for (int i = 0; i < n; ++i) total *= size_t(C);
      double best = 0;
      std::vector<uint16_t> pred(n);
      for (size_t code = 0; code < total; ++code) {
        size_t v = code;
        for (int i = 0; i < n; ++i, v /= size_t(C)) pred[i] = uint16_t(v % size_t(C));
        best = std::max(best, evaluate_3dovs_prediction(pred, gt, W, H).miou);
      }
      EXPECT_NEAR(ovs_ceiling(gt), best, 1e-12) << "C " << C << " trial " << trial;
      EXPECT_NEAR(evaluate_3dovs_prediction(pred, gt, W, H).ceiling, ovs_ceiling(gt), 0);
    }
  }
}

TEST(LerfPostprocess, ScaledWindowsAreLangSplatsAtTheReferenceWidth) {
  const LerfOptions d;
  for (auto [w, box, maj] :
       {std::tuple{1000, 30, 7}, {160, 5, 1}, {320, 10, 1}, {500, 15, 3}, {640, 19, 3}, {2000, 60, 13}, {10, 1, 1}}) {
    const LerfOptions o = scaled_lerf_options(w);
    EXPECT_EQ(o.box, box) << w;
    EXPECT_EQ(o.majority, maj) << w;
    EXPECT_EQ(o.threshold, d.threshold);
    EXPECT_EQ(o.boundary_d, d.boundary_d);
  }
  EXPECT_THROW(scaled_lerf_options(0), hgs::Error);
}
