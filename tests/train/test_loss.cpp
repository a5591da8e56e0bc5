// SSIM and L1: forward against a direct 2D brute-force SSIM, gradients against central finite differences
// in double precision, the float path against the double path, and the combined loss's gradient.
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <random>

#include "fd_check.h"
#include "train/loss.h"
#include "train/ssim.h"

namespace hgs::train {
namespace {

std::vector<double> random_image(int H, int W, int C, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::vector<double> v(size_t(H) * W * C);
  for (auto& x : v) x = u(rng);
  return v;
}

// SSIM gradients are checked within 1e-7 of their largest magnitude.
constexpr test::FdOptions kSsimFd{.h = 1e-6, .rtol = 0, .scale_atol = 1e-7, .noise_atol = 0};

// Direct definition: 2D window w(i) w(j) over an 11x11 neighbourhood with zero padding, per channel.
double brute_ssim(const std::vector<double>& x, const std::vector<double>& y, int H, int W, int C) {
  const double* w = ssim_window<double>();
  const double C1 = 1e-4, C2 = 9e-4;
  double total = 0;
  for (int yy = 0; yy < H; ++yy)
    for (int xx = 0; xx < W; ++xx)
      for (int c = 0; c < C; ++c) {
        double m1 = 0, m2 = 0, e11 = 0, e22 = 0, e12 = 0;
        for (int i = 0; i < 11; ++i)
          for (int j = 0; j < 11; ++j) {
            int py = yy + i - 5, px = xx + j - 5;
            if (py < 0 || py >= H || px < 0 || px >= W) continue;
            double a = x[(size_t(py) * W + px) * C + c], b = y[(size_t(py) * W + px) * C + c], k = w[i] * w[j];
            m1 += k * a;
            m2 += k * b;
            e11 += k * a * a;
            e22 += k * b * b;
            e12 += k * a * b;
          }
        double s11 = e11 - m1 * m1, s22 = e22 - m2 * m2, s12 = e12 - m1 * m2;
        total += (2 * m1 * m2 + C1) * (2 * s12 + C2) / ((m1 * m1 + m2 * m2 + C1) * (s11 + s22 + C2));
      }
  return total / (double(H) * W * C);
}

TEST(Ssim, WindowIsNormalisedGaussian) {
  const double* w = ssim_window<double>();
  double s = 0;
  for (int i = 0; i < 11; ++i) s += w[i];
  EXPECT_NEAR(s, 1.0, 1e-15);
  EXPECT_NEAR(w[5] / w[6], std::exp(1.0 / (2 * 1.5 * 1.5)), 1e-12);
  EXPECT_NEAR(w[0], w[10], 0);
}

TEST(Ssim, ForwardMatchesBruteForce) {
  SsimWorkspace<double> ws;
  for (auto [H, W, C] : {std::tuple{19, 23, 3}, std::tuple{6, 4, 3}, std::tuple{12, 30, 1}}) {
    auto x = random_image(H, W, C, 1), y = random_image(H, W, C, 2);
    // Make y correlated with x so the SSIM is not near 0.
    for (size_t i = 0; i < y.size(); ++i) y[i] = 0.7 * x[i] + 0.3 * y[i];
    double got = ssim(x.data(), y.data(), H, W, C, (double*)nullptr, ws);
    EXPECT_NEAR(got, brute_ssim(x, y, H, W, C), 1e-12) << H << "x" << W;
    EXPECT_NEAR(ssim(x.data(), x.data(), H, W, C, (double*)nullptr, ws), 1.0, 1e-12);
  }
}

TEST(Ssim, GradientMatchesFiniteDifferences) {
  SsimWorkspace<double> ws;
  for (auto [H, W] : {std::pair{14, 13}, std::pair{5, 8}}) {
    const int C = 3;
    auto x = random_image(H, W, C, 3), y = random_image(H, W, C, 4);
    for (size_t i = 0; i < y.size(); ++i) y[i] = 0.5 * x[i] + 0.5 * y[i];
    std::vector<double> g(x.size());
    ssim(x.data(), y.data(), H, W, C, g.data(), ws);
    const int h = H, w = W;
    auto f = [&] { return ssim(x.data(), y.data(), h, w, C, (double*)nullptr, ws); };
    const test::FdStats st =
        test::fd_check("ssim", x, test::all_indices(x.size(), x.size() > 200 ? 2 : 1), g, f, kSsimFd);
    EXPECT_GT(st.max_analytic, 1e-4);
  }
}

TEST(Ssim, RowBandsAreExactAndThreadIndependent) {
  // Tall enough for several row bands (one per thread): the same value and gradient bitwise for 1, 2 and 3
  // threads, the value equal to the brute force, the gradient to finite differences around band borders.
  const int H = 70, W = 17, C = 3;
  auto x = random_image(H, W, C, 7), y = random_image(H, W, C, 8);
  for (size_t i = 0; i < y.size(); ++i) y[i] = 0.6 * x[i] + 0.4 * y[i];
  const int saved = omp_get_max_threads();
  std::vector<std::vector<double>> grads;
  std::vector<double> values;
  for (int t : {1, 2, 3}) {
    omp_set_num_threads(t);
    SsimWorkspace<double> ws;
    std::vector<double> g(x.size());
    values.push_back(ssim(x.data(), y.data(), H, W, C, g.data(), ws));
    grads.push_back(g);
  }
  omp_set_num_threads(saved);
  EXPECT_EQ(values[0], values[1]);
  EXPECT_EQ(values[0], values[2]);
  EXPECT_EQ(grads[0], grads[1]);
  EXPECT_EQ(grads[0], grads[2]);
  EXPECT_NEAR(values[0], brute_ssim(x, y, H, W, C), 1e-12);
  omp_set_num_threads(std::max(2, saved));
  SsimWorkspace<double> ws;
  std::vector<int> idx;
  for (int row : {0, 22, 23, 24, 34, 35, 36, 46, 47, 69})
    for (int j = 0; j < W * C; j += 4) idx.push_back(row * W * C + j);
  auto f = [&] { return ssim(x.data(), y.data(), H, W, C, (double*)nullptr, ws); };
  test::FdOptions o = kSsimFd;
  o.h = 1e-4;  // gradients here are ~1e-3 (1/(HWC) scale): a larger step keeps rounding noise small
  const test::FdStats st = test::fd_check("ssim", x, idx, grads[0], f, o);
  omp_set_num_threads(saved);
  EXPECT_GT(st.max_analytic, 1e-5);
}

TEST(Ssim, FloatMatchesDouble) {
  const int H = 40, W = 50, C = 3;
  auto xd = random_image(H, W, C, 5), yd = random_image(H, W, C, 6);
  std::vector<float> xf(xd.begin(), xd.end()), yf(yd.begin(), yd.end()), gf(xd.size());
  std::vector<double> gd(xd.size());
  SsimWorkspace<double> wd;
  SsimWorkspace<float> wf;
  double sd = ssim(xd.data(), yd.data(), H, W, C, gd.data(), wd);
  float sf = ssim(xf.data(), yf.data(), H, W, C, gf.data(), wf);
  EXPECT_NEAR(sf, sd, 1e-5);
  double max_g = 0, max_err = 0;
  for (size_t i = 0; i < gd.size(); ++i) {
    max_g = std::max(max_g, std::abs(gd[i]));
    max_err = std::max(max_err, std::abs(gd[i] - gf[i]));
  }
  EXPECT_LT(max_err, 1e-3 * max_g);
}

TEST(L1, ValueAndGradient) {
  auto a = random_image(7, 9, 3, 7), b = random_image(7, 9, 3, 8);
  b[4] = a[4];  // an exact tie has gradient 0
  std::vector<double> g(a.size());
  double v = l1_loss(a.data(), b.data(), a.size(), g.data(), 2.0);
  double ref = 0;
  for (size_t i = 0; i < a.size(); ++i) ref += std::abs(a[i] - b[i]);
  EXPECT_NEAR(v, ref / a.size(), 1e-15);
  EXPECT_EQ(g[4], 0.0);
  std::vector<int> idx = test::all_indices(a.size());
  idx.erase(idx.begin() + 4);
  auto f = [&] { return 2.0 * l1_loss(a.data(), b.data(), a.size(), (double*)nullptr); };
  test::fd_check("l1", a, idx, g, f, {.h = 1e-7, .rtol = 1e-7, .rtol_of_fd = true, .scale_atol = 0, .noise_atol = 0});
}

TEST(PhotometricLoss, CombinesL1AndSsimGradients) {
  const int H = 24, W = 20;
  auto rd = random_image(H, W, 3, 9), gd = random_image(H, W, 3, 10);
  std::vector<float> r(rd.begin(), rd.end()), gt(gd.begin(), gd.end()), grad(r.size());
  PhotometricLoss loss(0.2f);
  LossValues v = loss(r.data(), gt.data(), H, W, grad.data());
  // Reference from the double-precision pieces.
  SsimWorkspace<double> ws;
  std::vector<double> gs(rd.size()), gl(rd.size());
  double s = ssim(rd.data(), gd.data(), H, W, 3, gs.data(), ws);
  double l1 = l1_loss(rd.data(), gd.data(), rd.size(), gl.data());
  EXPECT_NEAR(v.total, 0.8 * l1 + 0.2 * (1 - s), 1e-5);
  EXPECT_NEAR(v.l1, l1, 1e-6);
  EXPECT_NEAR(v.ssim, s, 1e-5);
  double mse = 0;
  for (size_t i = 0; i < rd.size(); ++i) mse += (rd[i] - gd[i]) * (rd[i] - gd[i]);
  EXPECT_NEAR(v.mse, mse / rd.size(), 1e-6);
  double max_err = 0, max_g = 0;
  for (size_t i = 0; i < rd.size(); ++i) {
    double ref = 0.8 * gl[i] - 0.2 * gs[i];
    max_err = std::max(max_err, std::abs(ref - grad[i]));
    max_g = std::max(max_g, std::abs(ref));
  }
  EXPECT_LT(max_err, 1e-4 * max_g);
  EXPECT_NEAR(psnr_from_mse(0.01), 20.f, 1e-5f);
}

}  // namespace
}  // namespace hgs::train
