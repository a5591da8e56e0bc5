// LERF's relevancy rule (query/relevancy.h): hand-computed values, and the map version against the scalar one
// and the exp form.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>

#include "core/error.h"
#include "query/relevancy.h"

using namespace hgs::query;

TEST(LerfRelevancy, HandValues) {
  const std::vector<float> q = {1, 0, 0}, e = {2, 0, 0};
  const std::vector<std::vector<float>> canon = {{0, 1, 0}, {1, 1.7320508f, 0}};  // cos 0 and 0.5 with e
  // p_0 = 1 / (1 + exp(10 (0 - 1))), p_1 = 1 / (1 + exp(10 (0.5 - 1))); the min is p_1.
  EXPECT_NEAR(lerf_relevancy(e.data(), q.data(), canon, 3), 1.0 / (1.0 + std::exp(-5.0)), 1e-6);
  EXPECT_NEAR(lerf_relevancy(e.data(), q.data(), {canon[0]}, 3), 1.0 / (1.0 + std::exp(-10.0)), 1e-6);
  // The embedding equal to a canonical phrase and orthogonal to the query: p = 1 / (1 + e^10).
  EXPECT_NEAR(lerf_relevancy(canon[0].data(), q.data(), canon, 3), 1.0 / (1.0 + std::exp(10.0)), 1e-9);
  // Zero embedding: all cosines 0 -> 0.5.
  const std::vector<float> z = {0, 0, 0};
  EXPECT_NEAR(lerf_relevancy(z.data(), q.data(), canon, 3), 0.5, 1e-7);
  EXPECT_THROW(lerf_relevancy(e.data(), q.data(), {}, 3), hgs::Error);
  EXPECT_THROW(lerf_relevancy(e.data(), q.data(), {{1, 0}}, 3), hgs::Error);
}

TEST(LerfRelevancy, MapMatchesScalarAndExpForm) {
  std::mt19937 rng(2);
  std::normal_distribution<float> nd;
  const int D = 16, N = 200;
  std::vector<float> feat(size_t(N) * D), q(D);
  std::vector<std::vector<float>> canon(4, std::vector<float>(D));
  for (auto& x : feat) x = nd(rng);
  for (auto& x : q) x = nd(rng);
  for (auto& c : canon)
    for (auto& x : c) x = nd(rng);
  std::fill(feat.begin(), feat.begin() + D, 0.f);  // one zero row
  auto map = lerf_relevancy_map(feat.data(), N, D, q.data(), canon);
  ASSERT_EQ(map.size(), size_t(N));
  for (int p = 0; p < N; ++p) {
    const float* e = &feat[size_t(p) * D];
    const double sq = cosine(e, q.data(), D);
    double ref = 1e9;
    for (auto& c : canon) {
      const double si = cosine(e, c.data(), D);
      ref = std::min(ref, std::exp(10 * sq) / (std::exp(10 * sq) + std::exp(10 * si)));
    }
    ASSERT_NEAR(map[p], ref, 1e-5) << p;
    ASSERT_NEAR(map[p], lerf_relevancy(e, q.data(), canon, D), 1e-6) << p;
  }
  EXPECT_FLOAT_EQ(map[0], 0.5f);
  // Rows with trailing columns (a render's further channels) give the same map; the extra columns are ignored.
  const int S = D + 3;
  std::vector<float> wide(size_t(N) * S, 7.f);
  for (int p = 0; p < N; ++p) std::copy_n(&feat[size_t(p) * D], D, &wide[size_t(p) * S]);
  EXPECT_EQ(lerf_relevancy_map(wide.data(), N, D, q.data(), canon, kLerfTemperature, S), map);
  EXPECT_THROW(lerf_relevancy_map(wide.data(), N, D, q.data(), canon, kLerfTemperature, D - 1), hgs::Error);
}
