// The statistics of `hgs ablate`'s tables (eval/paired_stats.h) on hand-computed numbers: paired differences
// clustered by scene (each scene's seeds averaged first, Student's t over the scene means), the mean and sample
// standard deviation, and the t table.
#include <gtest/gtest.h>

#include <cmath>

#include "eval/paired_stats.h"

using namespace hgs::eval;

TEST(PairedByScene, SeedsAveragedWithinASceneThenTOverScenes) {
  // Scene a: seeds 0.10, 0.30 -> 0.20; scene b: 0.40 -> 0.40 (one seed); scene c: 0.00, 0.00, 0.30 -> 0.10.
  // Scene means 0.2, 0.4, 0.1: mean 0.7 / 3; deviations -1/30, 5/30, -4/30, squares (1 + 25 + 16) / 900 =
  // 42 / 900, over n - 1 = 2: 21 / 900, sd = sqrt(21) / 30 = 0.152753; half = t(2) 4.303 * sd / sqrt(3).
  const ScenePaired p =
      paired_by_scene({{"a", 0.1}, {"b", 0.4}, {"c", 0.0}, {"a", 0.3}, {"c", 0.0}, {"c", 0.3}, {"b", std::nan("")}});
  EXPECT_EQ(p.scenes, 3);
  EXPECT_EQ(p.runs, 6);  // the NaN difference is no run
  EXPECT_NEAR(p.mean, 0.7 / 3, 1e-12);
  EXPECT_NEAR(p.half, 4.303 * (std::sqrt(21.0) / 30) / std::sqrt(3.0), 1e-12);
  // Treating the 6 runs as independent would give mean 1.1 / 6 and t(5) = 2.571 over 6 runs: not this.
  EXPECT_GT(std::abs(p.mean - 1.1 / 6), 0.04);
}

TEST(PairedByScene, OneSceneHasNoIntervalAndNoneIsEmpty) {
  const ScenePaired one = paired_by_scene({{"a", 0.1}, {"a", 0.2}});
  EXPECT_EQ(one.scenes, 1);
  EXPECT_EQ(one.runs, 2);
  EXPECT_NEAR(one.mean, 0.15, 1e-12);
  EXPECT_TRUE(std::isnan(one.half));
  const ScenePaired none = paired_by_scene({{"a", std::nan("")}});
  EXPECT_EQ(none.scenes, 0);
  EXPECT_EQ(none.runs, 0);
  EXPECT_TRUE(std::isnan(none.mean));
  // Two scenes, one seed each: d = 0.1, 0.3, sd = 0.1 * sqrt(2), half = 12.706 * 0.1 * sqrt(2) / sqrt(2).
  const ScenePaired two = paired_by_scene({{"x", 0.1}, {"y", 0.3}});
  EXPECT_NEAR(two.half, 12.706 * 0.1, 1e-12);
}

TEST(PairedStats, MeanStdAndTTable) {
  const auto [m, sd] = mean_std({1.0, 2.0, std::nan(""), 6.0});  // mean 3, squares 4 + 1 + 9 = 14, / 2 = 7
  EXPECT_DOUBLE_EQ(m, 3.0);
  EXPECT_NEAR(sd, std::sqrt(7.0), 1e-12);
  EXPECT_TRUE(std::isnan(mean_std({5.0}).second));
  EXPECT_TRUE(std::isnan(mean_std({}).first));
  EXPECT_DOUBLE_EQ(t975(1), 12.706);
  EXPECT_DOUBLE_EQ(t975(5), 2.571);
  EXPECT_DOUBLE_EQ(t975(30), 2.042);
  EXPECT_DOUBLE_EQ(t975(31), 1.96);
  EXPECT_TRUE(std::isnan(t975(0)));
}
