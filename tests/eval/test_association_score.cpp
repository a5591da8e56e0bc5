// `hgs masks score` (eval/association_score.h) on a hand-made scene: ids matched one to one whatever their numbers,
// IoU and boundary IoU of every (view, object) pair against a brute-force reference, the test views alone on request.
#include <gtest/gtest.h>

#include <cmath>
#include <vector>

#include "core/image.h"
#include "eval/association_score.h"
#include "masks/masks_test_util.h"
#include "test_util.h"

using namespace hgs;

namespace {

constexpr int W = 20, H = 16;

// Pixels of `m` (label k) within Chebyshev distance d of a pixel without it or of the image's edge.
std::vector<bool> boundary(const LabelMap& m, int k, int d) {
  std::vector<bool> b(m.v.size(), false);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (m.v[size_t(y) * W + x] != k) continue;
      for (int dy = -d; dy <= d; ++dy)
        for (int dx = -d; dx <= d; ++dx) {
          const int xx = x + dx, yy = y + dy;
          if (xx < 0 || yy < 0 || xx >= W || yy >= H || m.v[size_t(yy) * W + xx] != k) b[size_t(y) * W + x] = true;
        }
    }
  return b;
}

double iou(const std::vector<bool>& a, const std::vector<bool>& b) {
  long in = 0, un = 0;
  for (size_t i = 0; i < a.size(); ++i) in += a[i] && b[i], un += a[i] || b[i];
  return un ? double(in) / double(un) : 0.0;
}

void rect(LabelMap& m, int k, int x0, int y0, int x1, int y1) {
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) m.v[size_t(y) * W + x] = uint16_t(k);
}

}  // namespace

TEST(AssociationScore, IdsMatchedOneToOneAndBoundariesAgainstBruteForce) {
  test::TempDir tmp;
  std::vector<std::string> names;
  for (int i = 0; i < 9; ++i) names.push_back("frame_" + std::to_string(i) + ".png");  // views 0 and 8 are test
  test::make_tiny_scene(tmp.path, names, W, H);
  // Truth: objects 1 and 2; masks: ids 7 and 3 for them, object 1 shifted right by v % 3 pixels, object 2 missed
  // in view 4 and cut to its left half in view 5.
  double sum = 0, bsum = 0, found = 0, tsum = 0, tbsum = 0;
  int pairs = 0, above = 0, tpairs = 0;
  for (int v = 0; v < 9; ++v) {
    LabelMap gt(W, H), mk(W, H);
    rect(gt, 1, 2, 2, 10, 9);
    rect(gt, 2, 12, 6, 18, 14);
    rect(mk, 7, 2 + v % 3, 2, 10 + v % 3, 9);
    if (v == 5) rect(mk, 3, 12, 6, 15, 14);
    else if (v != 4) rect(mk, 3, 12, 6, 18, 14);
    save_label_png(tmp.path / "gt" / "instances" / names[v], gt);
    save_label_png(tmp.path / "masks" / names[v], mk);
    for (auto [g, p] : {std::pair{1, 7}, std::pair{2, 3}}) {
      std::vector<bool> a(gt.v.size()), b(gt.v.size());
      for (size_t i = 0; i < a.size(); ++i) a[i] = gt.v[i] == g, b[i] = mk.v[i] == p;
      const double i1 = iou(a, b), b1 = iou(boundary(gt, g, 1), boundary(mk, p, 1));
      sum += i1, bsum += b1, ++pairs;
      if (i1 >= 0.5) found += b1, ++above;
      if (v % 8 == 0) tsum += i1, tbsum += b1, ++tpairs;
    }
  }
  const eval::AssociationScore s = eval::score_association(tmp.path, tmp.path / "masks", 1);
  EXPECT_EQ(s.views, 9);
  EXPECT_EQ(s.pairs, pairs);
  EXPECT_EQ(s.match.at(1), 7);
  EXPECT_EQ(s.match.at(2), 3);
  EXPECT_NEAR(s.mean_iou, sum / pairs, 1e-12);
  EXPECT_NEAR(s.mean_biou, bsum / pairs, 1e-12);
  EXPECT_NEAR(s.found_mean_biou, found / above, 1e-12);
  EXPECT_LT(s.mean_biou, 1.0);
  EXPECT_GT(s.mean_biou, 0.0);
  const eval::AssociationScore t = eval::score_association(tmp.path, tmp.path / "masks", 1, true);
  EXPECT_EQ(t.views, 2);
  EXPECT_EQ(t.pairs, tpairs);
  EXPECT_NEAR(t.mean_iou, tsum / tpairs, 1e-12);
  EXPECT_NEAR(t.mean_biou, tbsum / tpairs, 1e-12);
}
