// Core pixels against a brute-force window check, and part folding on hand-made import.json entries.
#include <gtest/gtest.h>

#include <random>

#include "core/error.h"
#include "masks/per_view.h"
#include "masks/rle.h"

using namespace hgs;
using namespace hgs::masks;

TEST(CorePixels, MatchBruteForce) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 20; ++trial) {
    LabelMap m(7 + int(rng() % 20), 5 + int(rng() % 20));
    // Blocky labels so that cores exist.
    for (int y = 0; y < m.height; ++y)
      for (int x = 0; x < m.width; ++x) m.at(x, y) = uint16_t(((x / 4 + y / 3 + trial) % 5) * (rng() % 17 ? 1 : 7));
    for (int r : {0, 1, 2, 3}) {
      const std::vector<uint8_t> core = core_pixels(m, r);
      for (int y = 0; y < m.height; ++y)
        for (int x = 0; x < m.width; ++x) {
          bool same = true;
          for (int dy = -r; dy <= r; ++dy)
            for (int dx = -r; dx <= r; ++dx) {
              const int xx = x + dx, yy = y + dy;
              if (xx >= 0 && yy >= 0 && xx < m.width && yy < m.height) same &= m.at(xx, yy) == m.at(x, y);
            }
          ASSERT_EQ(core[size_t(y) * m.width + x], same ? 1 : 0) << trial << " r " << r << " " << x << "," << y;
        }
    }
  }
}

TEST(PartRoots, PartsFoldIntoAWholeTheyTileOnly) {
  std::map<int, MaskInfo> info;
  info[1] = {100, 10, 0};  // a whole its parts cover: kept 10 of 100 pixels
  info[2] = {45, 10, 1};   // its parts; 2 is itself covered by its own parts (kept 10 of 45)
  info[3] = {40, 40, 1};
  info[4] = {5, 5, 2};       // a part of a tiled part: folds to the top
  info[12] = {5, 5, 3};      // a small part of 3, which its parts do not tile: stays apart
  info[5] = {100, 90, 0};    // a whole that kept most of its pixels...
  info[6] = {60, 60, 5};     // ...but whose parts add up to 60% of it: tiled
  info[7] = {1000, 900, 0};  // a table holding a small thing: not tiled
  info[8] = {30, 30, 7};
  info[9] = {5000, 100, 0};  // a whole over max_area (0.8 of 6000 px): keeps its parts apart
  info[10] = {2000, 2000, 9};
  info[11] = {50, 50, 99};  // part of an id not in the list: stays itself
  const std::map<int, int> r = part_roots(info, 6000, 0.8);
  const std::map<int, int> want = {{1, 1}, {2, 1}, {3, 1}, {4, 1},   {5, 5},   {6, 5},
                                   {7, 7}, {8, 8}, {9, 9}, {10, 10}, {11, 11}, {12, 12}};
  EXPECT_EQ(r, want);
  // A cycle (corrupt input) ends.
  std::map<int, MaskInfo> cyc;
  cyc[1] = {10, 0, 2};
  cyc[2] = {10, 0, 1};
  EXPECT_EQ(part_roots(cyc, 100, 0.8).size(), 2u);
}

TEST(RobustSpread, IgnoresAFewStrayPoints) {
  std::vector<Eigen::Vector3d> p;
  for (int i = 0; i < 100; ++i) p.emplace_back(i % 10, i / 10, 0);  // a 10 x 10 grid around (4.5, 4.5)
  const double base = robust_spread(p);
  EXPECT_GT(base, 3.0);
  EXPECT_LT(base, 6.0);
  for (int i = 0; i < 5; ++i) p.emplace_back(1000, 1000, 1000);  // 5% far away: the 80th percentile barely moves
  EXPECT_LT(robust_spread(p), base + 1.0);
  EXPECT_EQ(robust_spread({}), 0.0);
  EXPECT_EQ(robust_spread({Eigen::Vector3d(1, 2, 3)}), 0.0);
  // Brute force on a line: median 0, distances 0..10 -> the 80th percentile of 21 values (index 16) is 8.
  std::vector<Eigen::Vector3d> line;
  for (int i = -10; i <= 10; ++i) line.emplace_back(i, 0, 0);
  EXPECT_EQ(robust_spread(line), 8.0);
}

namespace {
// A rectangle [x0, x1) x [y0, y1) as a SAM mask of a w x h image.
SourceMask rect(int w, int h, int x0, int y0, int x1, int y1, const std::string& name) {
  std::vector<uint8_t> px(size_t(w) * h, 0);
  for (int y = y0; y < y1; ++y)
    for (int x = x0; x < x1; ++x) px[size_t(y) * w + x] = 1;
  SourceMask m;
  m.rle = rle_encode(px, w, h);
  m.predicted_iou = 0.9;
  m.source = name;
  return m;
}
}  // namespace

TEST(ClipPartsToWholes, PartsKeepOnlyTheirPixelsInsideTheirWhole) {
  // 12 x 8 image: a table (id 1, the whole bottom half, not folded), a whole object (id 2, x 2..8, y 1..6), its two
  // halves dilated by one pixel (ids 3, 4; 3 sticks out at the left and top, 4 at the right and bottom), and a
  // small object (id 5) that is no part of anything.
  const int W = 12, H = 8;
  std::vector<SourceMask> masks = {rect(W, H, 0, 4, W, H, "table"), rect(W, H, 2, 1, 8, 6, "whole"),
                                   rect(W, H, 1, 0, 6, 7, "left half"), rect(W, H, 5, 1, 9, 7, "right half"),
                                   rect(W, H, 10, 1, 12, 3, "cup")};
  const std::map<int, int> root = {{1, 1}, {2, 2}, {3, 2}, {4, 2}, {5, 5}};
  Flattened f;
  ASSERT_TRUE(clip_parts_to_wholes(masks, root, W, H, f));
  // Brute force: every pixel's label is the smallest covering mask after clipping parts to their whole, so the
  // object (ids 2, 3, 4 together) covers exactly the whole's rectangle.
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const int l = f.labels.at(x, y);
      const bool in_whole = x >= 2 && x < 8 && y >= 1 && y < 6;
      EXPECT_EQ(l >= 2 && l <= 4, in_whole) << x << "," << y << " label " << l;
      if (!in_whole) {
        const int want = (x >= 10 && y >= 1 && y < 3) ? 5 : (y >= 4 ? 1 : 0);
        EXPECT_EQ(l, want) << x << "," << y;
      } else {
        EXPECT_NE(l, 2) << "parts tile the whole here, smaller wins: " << x << "," << y;  // left: x < 6, right: x >= 5
      }
    }
  // Unclipped, the union sticks out of the whole (the halves' dilation).
  const Flattened u = flatten_masks(masks, W, H);
  int outside = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      outside += (u.labels.at(x, y) == 3 || u.labels.at(x, y) == 4) && !(x >= 2 && x < 8 && y >= 1 && y < 6);
  EXPECT_GT(outside, 5);
  // Nothing folded: nothing to do.
  Flattened untouched;
  untouched.labels = LabelMap(1, 1);
  EXPECT_FALSE(clip_parts_to_wholes(masks, {{1, 1}, {2, 2}, {3, 3}}, W, H, untouched));
  EXPECT_EQ(untouched.labels.width, 1);
}

TEST(EdgeRampConfidence, MatchesBruteForceDistanceToTheNearestEdge) {
  std::mt19937 rng(11);
  for (int trial = 0; trial < 10; ++trial) {
    LabelMap m(9 + int(rng() % 15), 6 + int(rng() % 15));
    for (int y = 0; y < m.height; ++y)
      for (int x = 0; x < m.width; ++x) m.at(x, y) = uint16_t((x / 5 + (y / 4) * 2 + trial) % 3);
    std::vector<float> score(size_t(m.width) * m.height);
    for (auto& c : score) c = 0.6f + 0.4f * float(rng() % 100) / 100.f;
    for (int ramp : {1, 3, 6}) {
      std::vector<float> conf = score;
      edge_ramp_confidence(m, ramp, conf);
      for (int y = 0; y < m.height; ++y)
        for (int x = 0; x < m.width; ++x) {
          int best = m.width + m.height;  // brute force: nearest pixel with a 4-neighbour of another label
          for (int yy = 0; yy < m.height; ++yy)
            for (int xx = 0; xx < m.width; ++xx) {
              const uint16_t l = m.at(xx, yy);
              const bool edge = (xx > 0 && m.at(xx - 1, yy) != l) || (xx + 1 < m.width && m.at(xx + 1, yy) != l) ||
                                (yy > 0 && m.at(xx, yy - 1) != l) || (yy + 1 < m.height && m.at(xx, yy + 1) != l);
              if (edge) best = std::min(best, std::max(std::abs(xx - x), std::abs(yy - y)));
            }
          const size_t p = size_t(y) * m.width + x;
          const float want = score[p] * (0.5f + 0.5f * std::min(1.f, float(best) / float(ramp)));
          ASSERT_NEAR(conf[p], want, 1e-6) << trial << " ramp " << ramp << " at " << x << "," << y;
        }
    }
  }
  // No scores given: a score of 1 everywhere; an edge pixel gets 1/2.
  LabelMap two(4, 1);
  two.at(2, 0) = two.at(3, 0) = 1;
  std::vector<float> conf;
  edge_ramp_confidence(two, 2, conf);
  ASSERT_EQ(conf.size(), 4u);
  EXPECT_FLOAT_EQ(conf[0], 0.75f);
  EXPECT_FLOAT_EQ(conf[1], 0.5f);
  EXPECT_FLOAT_EQ(conf[2], 0.5f);
  EXPECT_FLOAT_EQ(conf[3], 0.75f);
  std::vector<float> wrong(3, 1.f);
  EXPECT_THROW(edge_ramp_confidence(two, 2, wrong), hgs::Error);
}
