// Unit tests of the small kernels of the hybrid method on hand-made inputs whose expected values are worked
// out by hand in the comments (never by calling the function under test): the confidence filter of eq. 2
// (apply_confidence, confident_pixels), the no-OF ablation's single-view hard association
// (single_view_assignment) and the mask pooling of the reference features (pool_reference, eq. 9 reference
// side; its upsampling form against pool_reference of the upsampled map).
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "core/error.h"
#include "hybrid/assign.h"
#include "hybrid/fusion.h"
#include "scene/scene.h"

using namespace hgs;
using namespace hgs::hybrid;

namespace {

LabelMap label_map(int w, int h, const std::vector<uint16_t>& v) {  // v [H, W]
  LabelMap m(w, h);
  m.v = v;
  return m;
}

}  // namespace

TEST(ApplyConfidence, BelowTau1BecomesBackgroundAndTau1ItselfKeepsTheLabel) {
  // Eq. 2: M_{u,k} = [zeta(I, k) >= tau1], so a pixel keeps its object label when its confidence is at least
  // tau1 (equality included) and becomes background (0) below it, whatever its label.
  const float tau1 = 0.5f;
  const float just_below = std::nextafter(tau1, 0.f);
  LabelMap m = label_map(3, 2,
                         {0, 1, 2,  // [H = 2, W = 3]
                          3, 1, 2});
  const std::vector<float> conf = {0.1f, just_below, tau1,  // [H, W]
                                   0.2f, 1.0f,       0.0f};
  apply_confidence(m, conf, tau1);
  // (0,0) background stays 0; (1,0) 0.4999999 < tau1 -> 0; (2,0) conf == tau1 keeps 2; (0,1) 0.2 -> 0;
  // (1,1) 1.0 keeps 1; (2,1) 0 -> 0.
  EXPECT_EQ(m.v, (std::vector<uint16_t>{0, 0, 2, 0, 1, 0}));
  // The observation mask of the fusion (V = 0 where unconfident) uses the same rule: conf >= tau1.
  EXPECT_EQ(confident_pixels(conf, tau1), (std::vector<uint8_t>{0, 0, 1, 0, 1, 0}));
}

TEST(GapPixels, UnlabelledPixelsAreNoObservationWhereTheMasksCoverTheView) {
  // 10 pixels, one unlabelled (90 % labelled) and two unlabelled (80 %).
  const LabelMap one = label_map(5, 2, {1, 1, 2, 2, 3, 3, 0, 4, 4, 4});
  const LabelMap two = label_map(5, 2, {1, 0, 2, 2, 3, 3, 0, 4, 4, 4});
  EXPECT_TRUE(gap_pixels(one, "background").empty());  // eq. 2 as written: every gap is background evidence
  EXPECT_EQ(gap_pixels(one, "unobserved"), (std::vector<uint8_t>{0, 0, 0, 0, 0, 0, 1, 0, 0, 0}));
  EXPECT_EQ(gap_pixels(one, "auto"), gap_pixels(one, "unobserved"));  // 90 % labelled: at the threshold
  EXPECT_TRUE(gap_pixels(two, "auto").empty());                       // 80 %: masks of objects only
  EXPECT_EQ(gap_pixels(two, "unobserved"), (std::vector<uint8_t>{0, 1, 0, 0, 0, 0, 1, 0, 0, 0}));
}

TEST(ApplyConfidence, NoConfidenceMapLeavesLabelsAndExtremeThresholds) {
  LabelMap m = label_map(2, 2, {4, 0, 2, 1});  // [2, 2]
  apply_confidence(m, {}, 0.9f);               // no confidence file: no filtering
  EXPECT_EQ(m.v, (std::vector<uint16_t>{4, 0, 2, 1}));
  const std::vector<float> conf = {0.0f, 0.3f, 0.7f, 1.0f};
  LabelMap keep = m;
  apply_confidence(keep, conf, 0.f);  // every confidence >= 0: all labels stay (0.0 included, equality)
  EXPECT_EQ(keep.v, (std::vector<uint16_t>{4, 0, 2, 1}));
  LabelMap none = m;
  apply_confidence(none, conf, 1.5f);  // nothing reaches 1.5: the whole map is background
  EXPECT_EQ(none.v, (std::vector<uint16_t>{0, 0, 0, 0}));
  LabelMap mid = m;
  apply_confidence(mid, conf, 0.7f);  // 0.7 >= 0.7 keeps label 2; 0.0 and 0.3 drop labels 4 and 0
  EXPECT_EQ(mid.v, (std::vector<uint16_t>{0, 0, 2, 1}));
}

TEST(SingleViewAssignment, FirstViewThatSeesTheGaussianDecidesAndUnseenKeepTheirQ) {
  // Four Gaussians, three views, L = 3 labels (background 0, objects 1 and 2). Table [N = 4, U = 3].
  const uint16_t X = kNoObservation;
  ObservationTable tab;
  tab.n = 4;
  tab.num_views = 3;
  tab.label = {X, 2, 1,   // Gaussian 0: view 0 does not see it, view 1 says object 2 (view 2's 1 is ignored)
               0, 1, 1,   // Gaussian 1: view 0 says background; the 2:1 majority for object 1 is ignored
               X, X, X,   // Gaussian 2: never observed -> keeps its previous q
               7, X, 1};  // Gaussian 3: label 7 >= L is not a label of this model -> the next valid view, 1
  std::vector<float> q = {0.2f, 0.3f, 0.5f,  // [N, L] previous q (soft, to see that a row is overwritten)
                          0.1f, 0.1f, 0.8f, 0.6f, 0.3f, 0.1f, 0.3f, 0.3f, 0.4f};
  single_view_assignment(tab, 3, q.data());
  EXPECT_EQ(q, (std::vector<float>{0, 0, 1,                    // one-hot of the first observation
                                   1, 0, 0, 0.6f, 0.3f, 0.1f,  // unchanged
                                   0, 1, 0}));
}

TEST(PoolReference, SumsFeaturesPerLabelThenNormalisesAndAbsentLabelsAreZero) {
  // Labels [H = 2, W = 3], L = 4 (0..3); label 2 is absent and label 7 >= L is ignored.
  const LabelMap labels = label_map(3, 2, {0, 1, 1, 3, 0, 7});
  // Features [H, W, D = 2], one row per pixel in the same order.
  const std::vector<float> f = {
      3,   4,   // label 0
      1,   0,   // label 1
      0,   2,   // label 1
      -2,  0,   // label 3
      0,   1,   // label 0
      100, 100  // label 7: not pooled anywhere
  };
  std::vector<float> z(4 * 2, 9.f), area(4, 9.f);  // [L, D], [L] pre-filled: every entry must be written
  pool_reference(f.data(), labels, 2, 4, z.data(), area.data());
  // Eq. 9 pools sum_p M S / (sum_p M + eps), then l2-normalises: the mean's scale cancels, so
  // z_l = sum / |sum|. Label 0: (3,4) + (0,1) = (3,5) -> (3,5)/sqrt(34) (normalising each pixel first would give
  // (0.6,1.8)/sqrt(3.6) = (0.316,0.949) instead). Label 1: (1,2)/sqrt(5). Label 2: absent -> 0.
  // Label 3: (-2,0) -> (-1,0).
  const double s34 = std::sqrt(34.0), s5 = std::sqrt(5.0);
  const double want[8] = {3 / s34, 5 / s34, 1 / s5, 2 / s5, 0, 0, -1, 0};
  for (int i = 0; i < 8; ++i) EXPECT_NEAR(z[i], want[i], 1e-6) << "z[" << i / 2 << "][" << i % 2 << "]";
  EXPECT_EQ(area, (std::vector<float>{2, 2, 0, 1}));  // pixel counts; label 7's pixel is counted nowhere
}

TEST(PoolReference, UpsampledOnePixelAtATimeGivesThePoolOfTheUpsampledMap) {
  // pool_reference_upsampled (no [H, W, D] map) against pool_reference of upsample_bilinear's map, bit for bit:
  // grids smaller than the image by non-integer factors, a one-cell-high grid, a grid larger than the image
  // (downsampling), labels >= L (skipped) and an absent label; random features and labels.
  struct Case {
    int gh, gw, H, W, D, L;
  };
  const Case cases[] = {{28, 37, 240, 320, 40, 6}, {1, 5, 7, 11, 3, 3}, {9, 13, 5, 6, 17, 4}, {7, 7, 7, 7, 8, 2}};
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  for (const Case& c : cases) {
    std::vector<float> grid(size_t(c.gh) * c.gw * c.D);
    for (float& x : grid) x = u(rng);
    LabelMap labels(c.W, c.H);
    // Label L - 1 never drawn (absent); L + 1 drawn (>= L: skipped by both).
    for (uint16_t& l : labels.v) l = uint16_t(std::uniform_int_distribution<int>(0, c.L + 1)(rng));
    for (uint16_t& l : labels.v)
      if (l == c.L - 1) l = 0;
    const std::vector<float> map = upsample_bilinear(grid.data(), c.gh, c.gw, c.D, c.H, c.W);
    std::vector<float> z0(size_t(c.L) * c.D), a0(c.L), z1(z0.size(), 7.f), a1(c.L, 7.f);
    pool_reference(map.data(), labels, c.D, c.L, z0.data(), a0.data());
    pool_reference_upsampled(grid.data(), c.gh, c.gw, labels, c.D, c.L, z1.data(), a1.data());
    const std::string at =
        std::to_string(c.gh) + "x" + std::to_string(c.gw) + " -> " + std::to_string(c.H) + "x" + std::to_string(c.W);
    EXPECT_EQ(a1, a0) << at;
    ASSERT_EQ(std::memcmp(z1.data(), z0.data(), z0.size() * sizeof(float)), 0) << at;
    EXPECT_EQ(a0[c.L - 1], 0.f) << at;
    EXPECT_GT(a0[0], 0.f) << at;
  }
}

TEST(PoolReference, ZeroSumGivesAZeroRowButKeepsTheArea) {
  // Two pixels of label 1 whose features cancel: the pooled direction is undefined, so the row is 0 (not NaN)
  // while the area still counts both pixels. Labels [1, 2], features [1, 2, D = 3], L = 2.
  const LabelMap labels = label_map(2, 1, {1, 1});
  const std::vector<float> f = {1, -2, 0.5f, -1, 2, -0.5f};
  std::vector<float> z(2 * 3, std::numeric_limits<float>::quiet_NaN()), area(2, -1.f);
  pool_reference(f.data(), labels, 3, 2, z.data(), area.data());
  EXPECT_EQ(z, (std::vector<float>(6, 0.f)));
  EXPECT_EQ(area, (std::vector<float>{0, 2}));
}

TEST(ApplyConfidence, AMapOfAnotherSizeIsAClearError) {
  LabelMap labels(3, 2);
  try {
    hybrid::apply_confidence(labels, std::vector<float>(5, 1.f), 0.5f);
    FAIL() << "no error";
  } catch (const hgs::Error& e) {
    EXPECT_NE(std::string(e.what()).find("a confidence map of 5 pixels for a mask of 6 pixels"), std::string::npos)
        << e.what();
  }
}
