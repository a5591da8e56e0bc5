// The objects-per-step approximation of eqs. 6 and 14 (HybridConfig::objects_per_step): sample_objects draws M of
// the J present objects uniformly without replacement, and ObjectLosses on the sample is an unbiased estimate of
// ObjectLosses on all of them: averaged over every M-subset, its value and its gradient for each object's
// channels equal the exact ones (checked here on a small random case with both terms, eq. 6 and BRO).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "hybrid/object_losses.h"

using namespace hgs;
using namespace hgs::hybrid;

TEST(ObjectSampling, DrawsMDistinctObjectsInTheirOrderEachWithProbabilityMOverJ) {
  const std::vector<int> present = {0, 2, 3, 5, 7, 8};  // J = 6 labels
  std::mt19937_64 rng(11);
  EXPECT_EQ(sample_objects(present, 0, rng), present);  // off: every object
  EXPECT_EQ(sample_objects(present, 6, rng), present);  // M >= J: every object
  EXPECT_EQ(sample_objects(present, 9, rng), present);
  const int M = 2, draws = 30000;
  std::vector<int> count(9, 0);
  std::vector<int> pair(81, 0);
  for (int t = 0; t < draws; ++t) {
    const std::vector<int> s = sample_objects(present, M, rng);
    ASSERT_EQ(s.size(), size_t(M));
    ASSERT_TRUE(std::is_sorted(s.begin(), s.end()));  // present is sorted: the sample keeps its order
    ASSERT_NE(s[0], s[1]);
    for (int k : s) {
      ASSERT_TRUE(std::count(present.begin(), present.end(), k) == 1) << k;
      ++count[k];
    }
    ++pair[s[0] * 9 + s[1]];
  }
  // Inclusion probability M / J = 1/3 for every object: binomial sd = sqrt(n p (1 - p)) ~ 82; 5 sd.
  for (int k : present) EXPECT_NEAR(count[k], draws / 3.0, 5 * std::sqrt(draws / 3.0 * 2 / 3)) << "object " << k;
  // Every one of the 15 pairs equally likely (p = 1/15, sd ~ 43).
  for (size_t a = 0; a < present.size(); ++a)
    for (size_t b = a + 1; b < present.size(); ++b)
      EXPECT_NEAR(pair[present[a] * 9 + present[b]], draws / 15.0, 5 * std::sqrt(draws / 15.0 * 14 / 15))
          << present[a] << "," << present[b];
}

TEST(ObjectSampling, AveragedOverAllSubsetsTheLossAndGradientAreTheExactOnes) {
  const int W = 28, H = 20, J = 4, M = 2;
  const size_t HW = size_t(W) * H;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  Image image(W, H, 3);
  for (auto& v : image.px) v = U(rng);
  LabelMap lab(W, H, 0);  // background 0, objects 1..3 in rectangles, so each object has an edge for BRO
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      if (x >= 3 && x < 12 && y >= 2 && y < 11) lab.at(x, y) = 1;
      if (x >= 15 && x < 25 && y >= 4 && y < 16) lab.at(x, y) = 2;
      if (x >= 5 && x < 10 && y >= 13 && y < 18) lab.at(x, y) = 3;
    }
  const std::vector<int> all = {0, 1, 2, 3};
  const ObjectLayout full{J, 0};
  std::vector<float> extra(HW * full.total());  // random object renders (colour) and opacities
  for (auto& v : extra) v = U(rng);
  HybridConfig cfg;  // eq. 6 and BRO on, with the scale rule and the scale-invariant gradient
  ObjectLosses exact_losses(cfg);
  std::vector<float> g_exact(extra.size(), 0.f);
  const ObjectLossValues ve = exact_losses(image, lab, extra.data(), full, all, g_exact.data());
  ASSERT_GT(ve.app, 0);
  ASSERT_GT(ve.bro, 0);

  // Every M-subset of the J objects, each with its own layout and render (the same values per object).
  double app = 0, bro = 0;
  std::vector<double> g_mean(extra.size(), 0.0);
  int subsets = 0;
  for (int a = 0; a < J; ++a)
    for (int b = a + 1; b < J; ++b) {
      const std::vector<int> objs = {all[a], all[b]};
      const int js[M] = {a, b};
      const ObjectLayout lay{M, 0};
      std::vector<float> ex(HW * lay.total()), g(HW * lay.total(), 0.f);
      for (size_t p = 0; p < HW; ++p)
        for (int j = 0; j < M; ++j) {
          for (int c = 0; c < 3; ++c)
            ex[p * lay.total() + lay.color(j) + c] = extra[p * full.total() + full.color(js[j]) + c];
          ex[p * lay.total() + lay.opacity(j)] = extra[p * full.total() + full.opacity(js[j])];
        }
      ObjectLosses losses(cfg);
      const ObjectLossValues v = losses(image, lab, ex.data(), lay, objs, g.data());
      app += v.app;
      bro += v.bro;
      for (size_t p = 0; p < HW; ++p)
        for (int j = 0; j < M; ++j)
          for (int c = 0; c < 3; ++c)
            g_mean[p * full.total() + full.color(js[j]) + c] += g[p * lay.total() + lay.color(j) + c];
      ++subsets;
    }
  ASSERT_EQ(subsets, 6);
  EXPECT_NEAR(app / subsets, ve.app, 1e-6 * ve.app);
  EXPECT_NEAR(bro / subsets, ve.bro, 1e-6 * ve.bro);
  double max_err = 0, max_g = 0;
  for (size_t i = 0; i < extra.size(); ++i) {
    max_err = std::max(max_err, std::abs(g_mean[i] / subsets - g_exact[i]));
    max_g = std::max(max_g, double(std::abs(g_exact[i])));
  }
  ASSERT_GT(max_g, 0);
  EXPECT_LT(max_err, 1e-5 * max_g);
}
