// kNN (k-d tree) against brute force, including duplicate points and clustered clouds; 3DGS init values.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>

#include "core/error.h"
#include "model/gaussian_model.h"
#include "model/knn.h"

namespace hgs {
namespace {

std::vector<float> brute_mean_sq(const std::vector<Eigen::Vector3f>& p, int k) {
  std::vector<float> out(p.size());
  for (size_t i = 0; i < p.size(); ++i) {
    std::vector<float> d;
    for (size_t j = 0; j < p.size(); ++j)
      if (j != i) d.push_back((p[i] - p[j]).squaredNorm());
    std::sort(d.begin(), d.end());
    int c = std::min<int>(k, d.size());
    double s = 0;
    for (int j = 0; j < c; ++j) s += d[j];
    out[i] = float(s / c);
  }
  return out;
}

TEST(Knn, MatchesBruteForce) {
  std::mt19937 rng(1);
  std::normal_distribution<float> nd;
  std::uniform_real_distribution<float> ud(-5, 5);
  std::vector<Eigen::Vector3f> p;
  // Clusters of very different density, a flat sheet and exact duplicates.
  for (int c = 0; c < 5; ++c) {
    Eigen::Vector3f ctr(ud(rng), ud(rng), ud(rng));
    float s = std::pow(10.f, -float(c));
    for (int i = 0; i < 300; ++i) p.push_back(ctr + s * Eigen::Vector3f(nd(rng), nd(rng), nd(rng)));
  }
  for (int i = 0; i < 400; ++i) p.emplace_back(ud(rng), ud(rng), 2.f);
  for (int i = 0; i < 20; ++i) p.push_back(p[i * 7]);
  for (int k : {1, 3, 8}) {
    auto got = knn_mean_sq_dist(p, k);
    auto ref = brute_mean_sq(p, k);
    ASSERT_EQ(got.size(), ref.size());
    for (size_t i = 0; i < p.size(); ++i)
      EXPECT_NEAR(got[i], ref[i], 1e-6f * std::max(1.f, ref[i])) << "k " << k << " i " << i;
  }
  auto idx = knn_indices(p, 3);
  for (size_t i = 0; i < p.size(); i += 37) {
    float d0 = (p[idx[i * 3]] - p[i]).squaredNorm(), d2 = (p[idx[i * 3 + 2]] - p[i]).squaredNorm();
    EXPECT_LE(d0, d2);
    EXPECT_NE(idx[i * 3], int(i));
  }
}

TEST(Knn, FewPointsAndAllIdentical) {
  std::vector<Eigen::Vector3f> p = {{0, 0, 0}, {1, 0, 0}, {0, 2, 0}};
  auto d = knn_mean_sq_dist(p, 3);  // only 2 neighbours exist
  EXPECT_FLOAT_EQ(d[0], 2.5f);
  EXPECT_FLOAT_EQ(d[1], 3.f);
  std::vector<Eigen::Vector3f> same(50, Eigen::Vector3f(1, 2, 3));
  for (float v : knn_mean_sq_dist(same, 3)) EXPECT_EQ(v, 0.f);
  EXPECT_THROW(knn_mean_sq_dist(p, 0), Error);
}

TEST(Init, ThreeDgsRule) {
  std::vector<Eigen::Vector3f> p = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0, 0, 1}, {5, 5, 5}, {5, 5, 5}};
  std::vector<Eigen::Vector3f> c(p.size(), Eigen::Vector3f(1.f, 0.5f, 0.f));
  GaussianModel m = init_from_points(p, c, 2);
  ASSERT_EQ(m.n, 6);
  EXPECT_EQ(m.sh.size(), 6u * 9 * 3);
  auto ref = brute_mean_sq(p, 3);
  for (int i = 0; i < 6; ++i) {
    float s = std::sqrt(std::max(ref[i], 1e-7f));
    for (int a = 0; a < 3; ++a) EXPECT_NEAR(std::exp(m.log_scale[i * 3 + a]), s, 1e-6f * s);
    EXPECT_NEAR(sigmoid(m.opacity_logit[i]), 0.1f, 1e-6f);
    EXPECT_EQ(m.quat[i * 4], 1.f);
    EXPECT_NEAR(sh_to_rgb(m.sh[i * 27 + 0]), 1.f, 1e-6f);
    EXPECT_NEAR(sh_to_rgb(m.sh[i * 27 + 1]), 0.5f, 1e-6f);
    EXPECT_NEAR(sh_to_rgb(m.sh[i * 27 + 2]), 0.f, 1e-6f);
    for (int j = 3; j < 27; ++j) EXPECT_EQ(m.sh[i * 27 + j], 0.f);
  }
  EXPECT_THROW(init_from_points({{0, 0, 0}}, {{0, 0, 0}}, 3), Error);
}

TEST(Model, GatherMovesEveryField) {
  GaussianModel m;
  m.sh_degree = 1;
  m.resize(3);
  m.add_extra("obj", 2);
  for (auto& f : m.fields())
    for (size_t i = 0; i < f.data->size(); ++i) (*f.data)[i] = float(i / f.dim);  // row index
  m.gather({2, 0, 2, 1});
  EXPECT_EQ(m.n, 4);
  for (auto& f : m.fields()) {
    ASSERT_EQ(f.data->size(), 4u * f.dim) << f.name;
    std::vector<float> rows = {2, 0, 2, 1};
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < f.dim; ++c) EXPECT_EQ((*f.data)[r * f.dim + c], rows[r]) << f.name;
  }
}

}  // namespace
}  // namespace hgs
