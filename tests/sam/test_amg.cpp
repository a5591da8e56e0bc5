// Automatic mask generator: the tiny model against the PyTorch reference (tests/data/sam/amg.json), and its
// parts (grid, stability score, box NMS) against hand-made cases and the defining properties of greedy NMS.
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "sam/amg.h"
#include "sam_test_util.h"

namespace hgs::test {
namespace {

TEST(SamAmg, PointGridIsCellCentresXFastest) {
  auto g = sam::point_grid(2);
  ASSERT_EQ(g.size(), 4u);
  EXPECT_FLOAT_EQ(g[0][0], 0.25f);
  EXPECT_FLOAT_EQ(g[0][1], 0.25f);
  EXPECT_FLOAT_EQ(g[1][0], 0.75f);
  EXPECT_FLOAT_EQ(g[1][1], 0.25f);
  EXPECT_FLOAT_EQ(g[2][0], 0.25f);
  EXPECT_FLOAT_EQ(g[2][1], 0.75f);
  auto g32 = sam::point_grid(32);
  EXPECT_FLOAT_EQ(g32[31][0], 1.f - 1.f / 64);
}

TEST(SamAmg, StabilityScoreCountsAboveBothOffsets) {
  std::vector<float> l = {-2.f, -0.5f, 0.5f, 2.f, 1.5f};
  EXPECT_FLOAT_EQ(sam::stability_score(l.data(), l.size(), 0.f, 1.f), 2.f / 4.f);
  EXPECT_FLOAT_EQ(sam::stability_score(l.data(), l.size(), 0.f, 0.25f), 3.f / 3.f);
  std::vector<float> none = {-5.f, -3.f};
  EXPECT_EQ(sam::stability_score(none.data(), none.size(), 0.f, 1.f), 0.f);
}

double iou(const std::array<float, 4>& a, const std::array<float, 4>& b) {
  const double iw = std::max(0.f, std::min(a[2], b[2]) - std::max(a[0], b[0]));
  const double ih = std::max(0.f, std::min(a[3], b[3]) - std::max(a[1], b[1]));
  const double u = double(a[2] - a[0]) * (a[3] - a[1]) + double(b[2] - b[0]) * (b[3] - b[1]) - iw * ih;
  return u > 0 ? iw * ih / u : 0;
}

TEST(SamAmg, BoxNmsIsGreedyByScore) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> U(0, 50), S(5, 30), P(0, 1);
  for (int trial = 0; trial < 20; ++trial) {
    std::vector<std::array<float, 4>> boxes;
    std::vector<float> scores;
    for (int i = 0; i < 40; ++i) {
      float x = U(rng), y = U(rng);
      boxes.push_back({x, y, x + S(rng), y + S(rng)});
      scores.push_back(P(rng));
    }
    const float th = 0.3f;
    std::vector<int> keep = sam::box_nms(boxes, scores, th);
    std::vector<bool> kept(boxes.size(), false);
    for (size_t k = 0; k < keep.size(); ++k) {
      kept[keep[k]] = true;
      if (k) {
        EXPECT_GE(scores[keep[k - 1]], scores[keep[k]]);
      }
      for (size_t j = 0; j < k; ++j) EXPECT_LE(iou(boxes[keep[j]], boxes[keep[k]]), th);
    }
    for (size_t i = 0; i < boxes.size(); ++i) {
      if (kept[i]) continue;
      bool covered = false;  // suppressed by a kept box of a higher score
      for (int k : keep) covered |= scores[k] >= scores[i] && iou(boxes[k], boxes[i]) > th;
      EXPECT_TRUE(covered) << "box " << i;
    }
    EXPECT_LT(keep.size(), boxes.size());
  }
}

TEST(SamAmg, MatchesTorchOnTheTinyModel) {
  nlohmann::json j = nlohmann::json::parse(std::ifstream(sam_data("amg.json")));
  const sam::AmgOptions o = reference_amg_options(j);
  sam::ImageEmbedding e = tiny_sam().embed(sam_image());
  int batches = 0;
  std::vector<sam::AmgMask> got = sam::generate_masks(tiny_sam(), e, o, [&](int /*done*/, int total) {
    ++batches;
    EXPECT_EQ(total, 25);
  });
  EXPECT_EQ(batches, 4);  // 25 points in batches of 7
  std::vector<size_t> shape;
  std::vector<float> ref_masks = sam_ref("amg_masks.npy", &shape);
  const auto& ref = j["masks"];
  ASSERT_GT(ref.size(), 3u);
  expect_amg_masks_match(got, ref, ref_masks, size_t(e.orig_h) * e.orig_w);
}

TEST(SamAmg, NmsAndThresholdsReduceTheSet) {
  sam::ImageEmbedding e = tiny_sam().embed(sam_image());
  sam::AmgOptions o;
  o.points_per_side = 5;
  o.pred_iou_thresh = 0.55f;
  o.stability_score_thresh = 0.02f;
  o.stability_score_offset = 0.25f;
  o.box_nms_thresh = 1.0f;
  const size_t all = sam::generate_masks(tiny_sam(), e, o).size();
  o.box_nms_thresh = 0.7f;  // the tiny model's masks all span the image: one survives
  EXPECT_EQ(sam::generate_masks(tiny_sam(), e, o).size(), 1u);
  o.box_nms_thresh = 1.0f;
  o.pred_iou_thresh = 0.65f;
  const size_t fewer = sam::generate_masks(tiny_sam(), e, o).size();
  EXPECT_LT(fewer, all);
  EXPECT_GT(fewer, 0u);
}

}  // namespace
}  // namespace hgs::test

namespace hgs::test {
namespace {

// Parses rows of '#' (1) and '.' (0).
std::vector<uint8_t> grid(const std::vector<std::string>& rows) {
  std::vector<uint8_t> m;
  for (const auto& r : rows)
    for (char c : r) m.push_back(c == '#');
  return m;
}

TEST(SamAmg, SmallHolesAreFilled) {
  // A 3-pixel hole and a 1-pixel hole inside, a large background outside (also a 0-region: kept).
  auto m = grid({"..........", ".########.", ".#...####.", ".########.", ".####.###.", ".########.", ".........."});
  auto want = grid({"..........", ".########.", ".########.", ".########.", ".########.", ".########.", ".........."});
  EXPECT_TRUE(sam::remove_small_regions(m, 10, 7, 4, true));
  EXPECT_EQ(m, want);
  EXPECT_FALSE(sam::remove_small_regions(m, 10, 7, 4, true));  // nothing small left
  // Threshold 3: the 3-pixel hole stays (regions smaller than the area are filled).
  auto m3 = grid({"..........", ".########.", ".#...####.", ".########.", ".####.###.", ".########.", ".........."});
  EXPECT_TRUE(sam::remove_small_regions(m3, 10, 7, 3, true));
  EXPECT_EQ(m3[2 * 10 + 2], 0);
  EXPECT_EQ(m3[4 * 10 + 5], 1);
}

TEST(SamAmg, SmallIslandsAreDroppedDiagonalsConnect) {
  auto m = grid({"##......#.", "##.......#", "..........", "....###...", "....###...", "....###...", "#........."});
  // Islands: the 2x2 block (4 px), the diagonal pair (2 px, 8-connected), the corner pixel (1), the 3x3 (9).
  EXPECT_TRUE(sam::remove_small_regions(m, 10, 7, 4, false));
  auto want = grid({"##........", "##........", "..........", "....###...", "....###...", "....###...", ".........."});
  EXPECT_EQ(m, want);
  // Every island small: the largest is kept.
  auto s = grid({"#.#", "...", "##."});
  EXPECT_TRUE(sam::remove_small_regions(s, 3, 3, 5, false));
  EXPECT_EQ(s, grid({"...", "...", "##."}));
}

TEST(SamAmg, MinRegionAreaChangesTheTinyModelsMasks) {
  sam::ImageEmbedding e = tiny_sam().embed(sam_image());
  sam::AmgOptions o;
  o.points_per_side = 5;
  o.pred_iou_thresh = 0.55f;
  o.stability_score_thresh = 0.02f;
  o.stability_score_offset = 0.25f;
  o.box_nms_thresh = 1.0f;
  std::vector<sam::AmgMask> raw = sam::generate_masks(tiny_sam(), e, o);
  o.min_mask_region_area = 20;
  std::vector<sam::AmgMask> clean = sam::generate_masks(tiny_sam(), e, o);
  ASSERT_EQ(clean.size(), raw.size());  // NMS off: only the masks change
  size_t changed = 0;
  for (const sam::AmgMask& c : clean) {
    std::vector<uint8_t> m = c.mask;  // a cleaned mask has nothing left to remove
    EXPECT_FALSE(sam::remove_small_regions(m, e.orig_w, e.orig_h, 20, true) &&
                 sam::remove_small_regions(m, e.orig_w, e.orig_h, 20, false));
    int area = 0;
    for (uint8_t v : c.mask) area += v;
    EXPECT_EQ(area, c.area);
  }
  for (const sam::AmgMask& r : raw) {
    std::vector<uint8_t> m = r.mask;
    changed += sam::remove_small_regions(m, e.orig_w, e.orig_h, 20, true) |
               sam::remove_small_regions(m, e.orig_w, e.orig_h, 20, false);
  }
  EXPECT_GT(changed, 0u);  // the speckled random masks do have small regions
}

}  // namespace
}  // namespace hgs::test
