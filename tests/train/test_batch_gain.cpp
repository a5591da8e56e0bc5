// The adaptive batch rule's gain (train/batch_gain.h): the squared norm against a brute-force sum and bitwise
// equal at any thread count; the gain at its two ends (views that agree: sqrt(G); independent views: 1) and its
// moving averages. (In a trainer: TrainerBatch.AdaptiveRule... in test_trainer.cpp.)
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <random>
#include <vector>

#include "train/batch_gain.h"

namespace hgs::train {
namespace {

TEST(BatchGain, SquaredNormIsTheSumOfSquaresBitwiseAtAnyThreadCount) {
  std::mt19937 rng(7);
  std::normal_distribution<float> d(0.f, 3.f);
  for (size_t n : {size_t(0), size_t(1), size_t(1000), size_t(16384), size_t(16385), size_t(100003)}) {
    std::vector<float> x(n);
    for (float& v : x) v = d(rng);
    long double ref = 0;  // brute force, every value in order
    for (float v : x) ref += (long double)v * (long double)v;
    const int t0 = omp_get_max_threads();
    omp_set_num_threads(1);
    const double one = squared_norm(x.data(), n);
    EXPECT_NEAR(one, double(ref), 1e-12 * double(ref) + 1e-300) << n;
    for (int t : {2, 3, 5}) {
      omp_set_num_threads(t);
      const double s = squared_norm(x.data(), n);
      EXPECT_EQ(s, one) << n << " values, " << t << " threads";
    }
    omp_set_num_threads(t0);
  }
}

TEST(BatchGain, SqrtGWhereTheViewsAgreeOneWhereTheyAreIndependent) {
  const int G = 4;
  // Four views with the same gradient g: ||gbar||^2 = ||g||^2 = the views' mean squared norm: r = 1, gain sqrt(G).
  AdamParam same;
  EXPECT_FLOAT_EQ(adaptive_gain(same, 2.5, 2.5, G, 0.99), 2.f);
  // Four views with gradients on disjoint supports and equal norms a: ||gbar||^2 = G a / G^2 = a / G against a
  // mean of a: r = 1 / G, gain 1 (Grendel's sqrt(G) alone).
  AdamParam apart;
  EXPECT_FLOAT_EQ(adaptive_gain(apart, 3.0 / G, 3.0, G, 0.99), 1.f);
  // In between: r = 1 / 2 gives sqrt(2).
  AdamParam half;
  EXPECT_FLOAT_EQ(adaptive_gain(half, 1.0, 2.0, G, 0.99), std::sqrt(2.f));
  // Nothing measured yet (no gradient): 1. One view per step: 1.
  AdamParam none;
  EXPECT_EQ(adaptive_gain(none, 0.0, 0.0, G, 0.99), 1.f);
  AdamParam single;
  EXPECT_EQ(adaptive_gain(single, 1.0, 1.0, 1, 0.99), 1.f);
  // The averages: the ratio of the two moving averages, not of the last step.
  AdamParam avg;
  adaptive_gain(avg, 1.0, 1.0, G, 0.5);      // averages 0.5, 0.5
  const float g = adaptive_gain(avg, 0.25, 1.0, G, 0.5);  // 0.375 / 0.75
  EXPECT_DOUBLE_EQ(avg.gain_batch, 0.375);
  EXPECT_DOUBLE_EQ(avg.gain_view, 0.75);
  EXPECT_FLOAT_EQ(g, float(std::sqrt(G * 0.5)));
  // Rounding cannot push the gain outside [1, sqrt(G)].
  AdamParam over;
  EXPECT_FLOAT_EQ(adaptive_gain(over, 2.0000001, 2.0, G, 0.9), 2.f);
}

}  // namespace
}  // namespace hgs::train
