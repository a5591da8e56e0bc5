// The SCL classes of a view (the background joins eq. 10 where a view holds fewer than two foreground objects,
// config.h scl_background), the InfoNCE anchor / positive sampling, and the configuration's round trip.
#include <gtest/gtest.h>

#include <map>
#include <random>

#include "core/error.h"
#include "hybrid/config.h"
#include "hybrid/data.h"
#include "hybrid/semantic.h"

using namespace hgs;

TEST(SclClasses, BackgroundJoinsOnlyWhereARuleAddsIt) {
  using V = std::vector<int>;
  // auto: fewer than two foreground objects -> the background (label 0) is a class, listed first.
  EXPECT_EQ(hybrid::scl_classes({3}, 500.f, "auto", 16), (V{0, 3}));
  EXPECT_EQ(hybrid::scl_classes({}, 500.f, "auto", 16), (V{0}));
  EXPECT_EQ(hybrid::scl_classes({2, 5}, 500.f, "auto", 16), (V{2, 5}));  // eq. 10 exactly
  // on: every view; off: never.
  EXPECT_EQ(hybrid::scl_classes({2, 5}, 500.f, "on", 16), (V{0, 2, 5}));
  EXPECT_EQ(hybrid::scl_classes({3}, 500.f, "off", 16), (V{3}));
  // A background smaller than an object may be is not a class either (min_mask_pixels).
  EXPECT_EQ(hybrid::scl_classes({3}, 15.f, "auto", 16), (V{3}));
  EXPECT_EQ(hybrid::scl_classes({3}, 16.f, "auto", 16), (V{0, 3}));
}

TEST(SclSampling, PositiveIsAnotherViewHoldingTheClassDrawnUniformly) {
  // Label 1 in views {0, 2, 5, 7}, label 2 only in view 2 (no positive anywhere else), label 0 in {2, 3}.
  const std::vector<std::vector<int>> views_with = {{2, 3}, {0, 2, 5, 7}, {2}};
  const std::vector<int> classes_u = {0, 1, 2};  // view u = 2 holds all three
  std::mt19937_64 rng(7);
  std::map<int, int> count1, count0;
  const int draws = 30000;
  for (int t = 0; t < draws; ++t) {
    const auto a = hybrid::draw_scl_anchors(classes_u, views_with, 2, rng);
    ASSERT_EQ(a.size(), 2u);  // label 2 has no other view: no anchor
    EXPECT_EQ(a[0].j, 0);
    EXPECT_EQ(a[0].v, 3);  // the background's only other view
    EXPECT_EQ(a[1].j, 1);
    ASSERT_NE(a[1].v, 2) << "the positive came from the anchor's own view";
    count0[a[0].v]++;
    count1[a[1].v]++;
  }
  // Uniform over {0, 5, 7}: each within 5 standard deviations of draws / 3 (sd = sqrt(n p (1 - p)) ~ 82).
  ASSERT_EQ(count1.size(), 3u);
  for (int v : {0, 5, 7}) EXPECT_NEAR(count1[v], draws / 3.0, 5 * 82) << "view " << v;
  // The first and last candidates are reachable from an anchor view at either end of the list.
  std::mt19937_64 rng2(1);
  std::map<int, int> from0;
  for (int t = 0; t < 3000; ++t) from0[hybrid::draw_scl_anchors({1}, views_with, 0, rng2)[0].v]++;
  EXPECT_EQ(from0.size(), 3u);
  EXPECT_EQ(from0.count(0), 0u);
  EXPECT_GT(from0[7], 0);
}

TEST(HybridConfigJson, SclBackgroundRoundTripsAndOlderConfigurationsKeepEq10) {
  hybrid::HybridConfig c;
  EXPECT_EQ(c.scl_background, "auto");
  c.scl_background = "on";
  EXPECT_EQ(hybrid::HybridConfig::from_json(c.to_json()).scl_background, "on");
  // Written before the option existed: trained with eq. 10 as written.
  nlohmann::json old = hybrid::HybridConfig{}.to_json();
  old.erase("scl_background");
  EXPECT_EQ(hybrid::HybridConfig::from_json(old).scl_background, "off");
  old["scl_background"] = "sometimes";
  try {
    hybrid::HybridConfig::from_json(old);
    FAIL() << "no error";
  } catch (const hgs::Error& e) {
    EXPECT_NE(std::string(e.what()).find("scl_background must be auto, on or off"), std::string::npos) << e.what();
  }
}
