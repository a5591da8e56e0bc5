// Core pixels against a brute-force window check, and part folding on hand-made import.json entries.
#include <gtest/gtest.h>

#include <random>

#include "masks/per_view.h"

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
  info[1] = {100, 10, 0};   // a whole its parts cover: kept 10 of 100 pixels
  info[2] = {45, 10, 1};    // its parts; 2 is itself covered by its own parts (kept 10 of 45)
  info[3] = {40, 40, 1};
  info[4] = {5, 5, 2};      // a part of a tiled part: folds to the top
  info[12] = {5, 5, 3};     // a small part of 3, which its parts do not tile: stays apart
  info[5] = {100, 90, 0};   // a whole that kept most of its pixels...
  info[6] = {60, 60, 5};    // ...but whose parts add up to 60% of it: tiled
  info[7] = {1000, 900, 0}; // a table holding a small thing: not tiled
  info[8] = {30, 30, 7};
  info[9] = {5000, 100, 0}; // a whole over max_area (0.8 of 6000 px): keeps its parts apart
  info[10] = {2000, 2000, 9};
  info[11] = {50, 50, 99};  // part of an id not in the list: stays itself
  const std::map<int, int> r = part_roots(info, 6000, 0.8);
  const std::map<int, int> want = {{1, 1}, {2, 1}, {3, 1}, {4, 1}, {5, 5}, {6, 5}, {7, 7}, {8, 8}, {9, 9}, {10, 10}, {11, 11}, {12, 12}};
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
