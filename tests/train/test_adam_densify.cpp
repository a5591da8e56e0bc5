// Adam against a hand computation of torch's update; densification clone/split/prune on hand-made
// Gaussians, with Adam moments following their rows; opacity reset.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <random>
#include <type_traits>

#include "core/error.h"
#include "core/half.h"

#include "train/adam.h"
#include "train/densify.h"

namespace hgs::train {
namespace {

TEST(Adam, MatchesHandComputation) {
  Adam adam;
  AdamParam& p = adam.add("x", 2, 1, 0.1f);
  p.lr = {0.1f, 0.01f};  // per-column rates
  std::vector<float> x = {1.f, -2.f};
  // Step 1, g = (0.5, -3): m = 0.1 g, v = 0.001 g^2, mhat = g, vhat = g^2 -> x -= lr * sign(g) (eps tiny).
  std::vector<float> g = {0.5f, -3.f};
  adam.update(p, x.data(), g.data(), 1);
  EXPECT_NEAR(x[0], 1.f - 0.1f, 1e-6f);
  EXPECT_NEAR(x[1], -2.f + 0.01f, 1e-6f);
  // Step 2, g = (-1, 1), in double by hand.
  g = {-1.f, 1.f};
  adam.update(p, x.data(), g.data(), 1);
  double m0 = 0.9 * 0.05 + 0.1 * -1, v0 = 0.999 * 0.001 * 0.25 + 0.001 * 1;
  double m1 = 0.9 * -0.3 + 0.1 * 1, v1 = 0.999 * 0.001 * 9 + 0.001 * 1;
  double bc1 = 1 - 0.81, bc2 = 1 - 0.999 * 0.999;
  double x0 = 0.9 - 0.1 / bc1 * m0 / (std::sqrt(v0) / std::sqrt(bc2) + 1e-15);
  double x1 = -1.99 - 0.01 / bc1 * m1 / (std::sqrt(v1) / std::sqrt(bc2) + 1e-15);
  EXPECT_NEAR(x[0], x0, 1e-6);
  EXPECT_NEAR(x[1], x1, 1e-6);
  EXPECT_NEAR(p.m[0], m0, 1e-7);
  EXPECT_NEAR(p.v[1], v1, 1e-4 * v1);  // float (1 - beta2) vs the exact 0.001
  // Uniform-rate path gives the same as the per-column path.
  Adam a2;
  AdamParam& q = a2.add("y", 3, 2, 0.05f);
  std::vector<float> y = {1, 2, 3, 4, 5, 6}, gy = {0.1f, -0.2f, 0.3f, 0, 1, -1};
  a2.update(q, y.data(), gy.data(), 2);
  EXPECT_NEAR(y[0], 0.95f, 1e-6f);
  EXPECT_NEAR(y[1], 2.05f, 1e-6f);
  EXPECT_FLOAT_EQ(y[3], 4.f);  // zero gradient, zero moments: no move
}

// Random gradients [n, d] for a few steps; row r has no gradient in steps where (step + r) % 3 == 0.
struct RowSteps {
  int n, d;
  std::vector<std::vector<float>> g;
  RowSteps(int n_, int d_, int steps, unsigned seed) : n(n_), d(d_) {
    std::mt19937 rng(seed);
    std::normal_distribution<float> N(0, 1);
    for (int s = 0; s < steps; ++s) {
      g.emplace_back(size_t(n) * d);
      for (int r = 0; r < n; ++r)
        for (int c = 0; c < d; ++c) g[s][size_t(r) * d + c] = (s + r) % 3 == 0 ? 0.f : N(rng) * (1 + c % 5);
    }
  }
  bool has(int s, long r) const { return (s + r) % 3 != 0; }
  // Every step on two optimisers side by side: float32 values x32 and values x (float32 or half) under `a`.
  template <class X>
  void run(Adam& a32, AdamParam& p32, float* x32, Adam& a, AdamParam& p, X* x) const {
    for (size_t s = 0; s < g.size(); ++s) {
      auto grad = [&](long r, float* out) {
        if (!has(int(s), r)) return false;
        std::copy_n(&g[s][size_t(r) * d], d, out);
        return true;
      };
      a32.update_rows(p32, x32, n, grad);
      a.update_rows(p, x, n, grad);
    }
  }
};

TEST(Adam, RowUpdateMatchesDenseOnRowsWithGradient) {
  // float32 moments: update_rows is the dense update on the rows that have a gradient, and leaves the others.
  const int n = 5, d = 40;
  RowSteps rs(n, d, 6, 11);
  Adam dense, rows;
  AdamParam& pd = dense.add("x", d, n, 0.01f);
  AdamParam& pr = rows.add("x", d, n, 0.01f);
  std::vector<float> xd(size_t(n) * d, 0.5f), xr = xd;
  for (int s = 0; s < 6; ++s) {
    // Dense reference per row: the rows without a gradient are skipped by hand.
    std::vector<float> before = xd, mb = pd.m, vb = pd.v;
    dense.update(pd, xd.data(), rs.g[s].data(), n);
    for (int r = 0; r < n; ++r)
      if (!rs.has(s, r))
        for (int c = 0; c < d; ++c) {
          const size_t i = size_t(r) * d + c;
          xd[i] = before[i], pd.m[i] = mb[i], pd.v[i] = vb[i];
        }
    int calls = 0;
    rows.update_rows(pr, xr.data(), n, [&](long r, float* g) {
#pragma omp atomic
      ++calls;
      if (!rs.has(s, r)) return false;
      std::copy_n(&rs.g[s][size_t(r) * d], d, g);
      return true;
    });
    EXPECT_EQ(calls, n);
  }
  for (size_t i = 0; i < xd.size(); ++i) {
    EXPECT_NEAR(xr[i], xd[i], 1e-6f) << i;
    EXPECT_NEAR(pr.m[i], pd.m[i], 1e-6f) << i;
  }
}

TEST(Adam, Bf16MomentsTrackFloat32) {
  // bfloat16 moments (vector path for columns 0..31, scalar tail 32..39) follow the float32 run closely.
  const int n = 4, d = 40, steps = 200;
  RowSteps rs(n, d, steps, 5);
  Adam a32, a16;
  AdamParam& p32 = a32.add("x", d, n, 1e-3f);
  AdamParam& p16 = a16.add("x", d, n, 1e-3f, true);
  EXPECT_TRUE(p16.m.empty());
  EXPECT_EQ(p16.m16.size(), size_t(n) * d);
  std::vector<float> x32(size_t(n) * d, 0.f), x16 = x32;
  rs.run(a32, p32, x32.data(), a16, p16, x16.data());
  // Each step moves a value by about lr = 1e-3; after 200 steps the two runs agree to a few steps' worth.
  double worst = 0, moved = 0;
  for (size_t i = 0; i < x32.size(); ++i) {
    worst = std::max(worst, double(std::abs(x16[i] - x32[i])));
    moved = std::max(moved, double(std::abs(x32[i])));
    // Stochastic rounding adds an unbiased error of up to one bf16 unit per step, which the moving averages
    // accumulate as a random walk: for gradient scale s (1..5 by column), m (std ~0.23 s, memory ~10 steps)
    // stays within ~4e-3 s and v (~s^2, memory ~1000 steps) within a few percent of s^2.
    const double sc = 1 + (i % d) % 5;
    EXPECT_NEAR(bf16_to_float(p16.m16[i]), p32.m[i], 6e-3 * sc) << i;
    EXPECT_NEAR(bf16_to_float(p16.v16[i]), p32.v[i], 0.08 * sc * sc) << i;
  }
  EXPECT_GT(moved, 0.02);
  EXPECT_LT(worst, 5e-3) << "bf16 moments drifted from the float32 run";
}

TEST(Adam, TinyGradientsStayFinite) {
  // Gradients whose squares are float denormals (or zero) must give finite, bounded steps on both the vector
  // path (columns 0..31) and the scalar tail, with float32 and bfloat16 moments: an estimate-based 1/sqrt, for
  // one, treats a denormal v as 0 and turns the step into NaN.
  const int n = 4, d = 40;
  const float tiny[n] = {1e-20f, 1e-30f, 3e-23f, 0.f};
  for (bool bf16 : {false, true}) {
    Adam a;
    AdamParam& p = a.add("x", d, n, 1e-3f, bf16);
    std::vector<float> x(size_t(n) * d, 1.f);
    for (int t = 1; t <= 5; ++t) {
      a.update_rows(p, x.data(), n, [&](long i, float* g) {
        for (int c = 0; c < d; ++c) g[c] = (t == 1 && i == 3) ? 1.f : tiny[i] * float(1 + c % 3);
        return true;
      });
    }
    for (size_t k = 0; k < x.size(); ++k) {
      ASSERT_TRUE(std::isfinite(x[k])) << (bf16 ? "bf16 " : "f32 ") << k;
      EXPECT_LE(std::abs(x[k] - 1.f), 5 * 5e-3f) << k;  // 5 steps of at most a few lr each
    }
  }
}

TEST(Adam, HalfValuesTrackFloat32) {
  // Values stored in IEEE half (the hybrid method's f_n) with bfloat16 moments follow the all-float32 run; a
  // step far below half a unit still moves the value on average (stochastic rounding).
  const int n = 4, d = 40, steps = 200;
  RowSteps rs(n, d, steps, 9);
  Adam a32, a16;
  AdamParam& p32 = a32.add("x", d, n, 1e-3f);
  AdamParam& p16 = a16.add("x", d, n, 1e-3f, true);
  std::vector<float> x32(size_t(n) * d, 0.25f);
  std::vector<uint16_t> x16(x32.size(), float_to_half(0.25f));
  rs.run(a32, p32, x32.data(), a16, p16, x16.data());
  double worst = 0, moved = 0;
  for (size_t i = 0; i < x32.size(); ++i) {
    worst = std::max(worst, double(std::abs(half_to_float(x16[i]) - x32[i])));
    moved = std::max(moved, double(std::abs(x32[i] - 0.25f)));
  }
  EXPECT_GT(moved, 0.02);
  // Half units near 0.25 are 2.4e-4; stochastic rounding adds an unbiased random walk of that size per step.
  EXPECT_LT(worst, 4e-3) << "half-precision values drifted from the float32 run";
  // Tiny steps: lr 1e-5 on values near 1 (half unit 9.8e-4); 1000 steps of a constant gradient move x by 0.01.
  Adam at;
  AdamParam& pt = at.add("x", 64, 1, 1e-5f, true);
  std::vector<uint16_t> xt(64, float_to_half(1.f));
  std::vector<float> g(64, 1.f);
  for (int s = 0; s < 1000; ++s) {
    at.update_row(pt, xt.data(), 0, g.data());
  }
  double mean = 0;
  for (uint16_t h : xt) mean += half_to_float(h) / 64;
  EXPECT_NEAR(mean, 0.99, 2e-3);
}

TEST(Adam, Bf16SecondMomentDecaysUnderStochasticRounding) {
  // v = 0.999 v per step is a 0.1% change, below half a bf16 unit: round-to-nearest would keep v = 1 forever.
  // Stochastic rounding follows 0.999^t in expectation. Zero gradients through update_row (all columns).
  const int d = 64;
  Adam a;
  AdamParam& p = a.add("x", d, 1, 1e-3f, true);
  std::fill(p.v16.begin(), p.v16.end(), float_to_bf16(1.f));
  std::vector<float> x(d, 0.f), g(d, 0.f);
  for (int s = 0; s < 1000; ++s) {
    a.update_row(p, x.data(), 0, g.data());
  }
  double mean = 0;
  for (int c = 0; c < d; ++c) mean += bf16_to_float(p.v16[c]) / d;
  EXPECT_NEAR(mean, std::pow(0.999, 1000), 0.02);
  EXPECT_EQ(float_to_bf16(1.f + 1e-3f), float_to_bf16(1.f));  // what round-to-nearest would do
}

// The bfloat16-moment row rule one element at a time, written out from adam.h and core/half.h: the reference the
// 16- and 8-column loops are held to, bit for bit. x: the row's values (float or half), t: the update's step.
template <class X>
void bf16_row_reference(const AdamParam& p, X* x, long row, const float* g, uint16_t* m, uint16_t* v, long t, float b1,
                        float b2) {
  const float step = p.lr[0] / float(1.0 - std::pow(double(b1), double(t)));
  const float inv_sqrt_bc2 = float(1.0 / std::sqrt(1.0 - std::pow(double(b2), double(t))));
  const size_t o = size_t(row) * p.dim;
  const uint32_t base = uint32_t(o) * 0x9E3779B9u ^ uint32_t(t) * 0x7FEB352Du;
  const int blocks = p.dim / 16 * 16;  // columns in whole blocks of 16; the rest follow the scalar tail's v
  for (int c = 0; c < p.dim; ++c) {
    const float gc = g[c];
    const float mi = std::fma(b1, bf16_to_float(m[o + c]), (1 - b1) * gc);
    const float vi = c < blocks ? std::fma(b2, bf16_to_float(v[o + c]), (1 - b2) * (gc * gc))
                                : std::fma(b2, bf16_to_float(v[o + c]), ((1 - b2) * gc) * gc);
    const uint32_t r = hash32(base + uint32_t(c) * 0x9E3779B9u);
    m[o + c] = float_to_bf16_stochastic(mi, r);
    v[o + c] = float_to_bf16_stochastic(vi, r >> 16);
    const float den = std::fma(std::sqrt(vi), inv_sqrt_bc2, p.eps);
    if constexpr (std::is_same_v<X, float>) {
      x[o + c] = x[o + c] - (step * mi) / den;
    } else {
      const float nx = half_to_float(x[o + c]) - (step * mi) / den;
      x[o + c] = float_to_half_stochastic(nx, (r * 0x9E3779B1u) >> 19);
    }
  }
}

template <class X>
void check_bf16_rows(bool avx512) {
  // 3 rows of 53 columns: three blocks of 16 (the AVX-512 loop), of which the AVX2 loop takes the same blocks in
  // halves, and a tail of 5 (scalar); gradients from 1e-6 to 10, zeros, and values in float or half.
  const int n = 3, d = 53;
  Adam a;
  AdamParam& p = a.add("x", d, n, 2e-3f, true);
  std::mt19937 rng(17);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  std::vector<X> x(size_t(n) * d);
  for (auto& e : x) {
    if constexpr (std::is_same_v<X, float>) e = u(rng);
    else e = float_to_half(u(rng));
  }
  std::vector<X> xr = x;
  std::vector<uint16_t> mr = p.m16, vr = p.v16;
  std::vector<float> g(d);
  for (long t = 1; t <= 40; ++t)
    for (long row = 0; row < n; ++row) {
      for (int c = 0; c < d; ++c) g[c] = (c + row + t) % 7 == 0 ? 0.f : u(rng) * std::pow(10.f, float(c % 8) - 6);
      // update_row advances the parameter's step: rows take turns, so the row's update is step p.step + 1.
      const long ts = p.step + 1;
      a.update_row(p, x.data(), row, g.data());
      bf16_row_reference(p, xr.data(), row, g.data(), mr.data(), vr.data(), ts, a.beta1, a.beta2);
    }
  for (size_t k = 0; k < x.size(); ++k) {
    ASSERT_EQ(p.m16[k], mr[k]) << (avx512 ? "avx512" : "avx2") << " m, element " << k;
    ASSERT_EQ(p.v16[k], vr[k]) << (avx512 ? "avx512" : "avx2") << " v, element " << k;
    ASSERT_EQ(std::memcmp(&x[k], &xr[k], sizeof(X)), 0) << (avx512 ? "avx512" : "avx2") << " x, element " << k;
  }
}

TEST(Adam, Bf16RowLoopsGiveTheElementRulesBits) {
  // The 16-column (AVX-512) and 8-column (AVX2) loops against the rule written out per element.
  const bool had = adam_avx512();
  for (bool wide : {false, true}) {
    if (!set_adam_avx512(wide)) {
      std::printf("[  NOTE    ] no AVX-512 on this CPU: the 16-column loop is not checked\n");
      continue;
    }
    check_bf16_rows<float>(wide);
    check_bf16_rows<uint16_t>(wide);
  }
  set_adam_avx512(had);
}

TEST(Adam, Bf16GatherAndReset) {
  Adam adam;
  AdamParam& p = adam.add("x", 2, 3, 0.1f, true);
  for (int i = 0; i < 6; ++i) p.m16[i] = uint16_t(i), p.v16[i] = uint16_t(10 + i);
  adam.gather({2, 0, 2}, {0, 0, 1});
  EXPECT_EQ(p.m16, (std::vector<uint16_t>{4, 5, 0, 1, 0, 0}));
  EXPECT_EQ(p.v16, (std::vector<uint16_t>{14, 15, 10, 11, 0, 0}));
  adam.reset_moments("x");
  EXPECT_EQ(p.v16, std::vector<uint16_t>(6, 0));
  std::vector<float> x(6), g(6);
  EXPECT_THROW(adam.update(p, x.data(), g.data(), 3), Error);  // bf16 moments need update_rows
}

TEST(Adam, GatherCarriesMoments) {
  Adam adam;
  AdamParam& p = adam.add("x", 2, 3, 0.1f);
  for (int i = 0; i < 6; ++i) p.m[i] = float(i), p.v[i] = float(10 + i);
  adam.gather({2, 0, 2}, {0, 0, 1});
  EXPECT_EQ(p.m, (std::vector<float>{4, 5, 0, 1, 0, 0}));
  EXPECT_EQ(p.v, (std::vector<float>{14, 15, 10, 11, 0, 0}));
}

struct Fixture {
  GaussianModel m;
  Adam adam;
  DensifyStats stats;
  // Four Gaussians: 0 small + high gradient (clone), 1 large + high gradient (split), 2 low gradient,
  // 3 transparent (pruned).
  Fixture() {
    m.sh_degree = 0;
    m.resize(4);
    m.add_extra("obj", 2);
    float ls[4] = {std::log(0.005f), std::log(0.5f), std::log(0.005f), std::log(0.005f)};
    float op[4] = {0.5f, 0.6f, 0.7f, 0.001f};
    for (int i = 0; i < 4; ++i) {
      for (int a = 0; a < 3; ++a) m.mean[i * 3 + a] = float(10 * i + a);
      for (int a = 0; a < 3; ++a) m.log_scale[i * 3 + a] = ls[i] + (a == 1 ? std::log(0.5f) : 0.f);
      m.opacity_logit[i] = inverse_sigmoid(op[i]);
      m.sh[i * 3] = float(i);
      m.extras[0].data[i * 2] = float(100 + i);
    }
    for (auto& f : m.fields()) {
      AdamParam& p = adam.add(f.name, f.dim, m.n, 0.1f);
      for (int i = 0; i < m.n; ++i)
        for (int c = 0; c < f.dim; ++c) p.m[i * f.dim + c] = float(i + 1), p.v[i * f.dim + c] = float(i + 1) * 2;
    }
    stats.reset(4);
    // Two views; gradients in pixels at 200x100: NDC norm = |(gx * 100, gy * 50)|.
    float g1[8] = {3e-6f, 0, 0, 4e-6f, 1e-7f, 0, 0, 0};
    int r1[4] = {3, 5, 2, 2};
    stats.add(g1, r1, 4, 200, 100);
    float g2[8] = {3e-6f, 0, 0, 4e-6f, 1e-7f, 0, 0, 0};
    int r2[4] = {4, 0, 1, 0};  // Gaussian 1 and 3 not visible in view 2
    stats.add(g2, r2, 4, 200, 100);
  }
};

TEST(Densify, StatisticsInNdcUnits) {
  Fixture f;
  EXPECT_EQ(f.stats.count, (std::vector<int>{2, 1, 2, 1}));
  EXPECT_NEAR(f.stats.grad_accum[2], 2 * 1e-5f, 1e-10f);
  EXPECT_NEAR(f.stats.grad_accum[0], 2 * 3e-4f, 1e-9f);
  EXPECT_NEAR(f.stats.grad_accum[1], 2e-4f, 1e-9f);  // 4e-6 * 50, seen once
  EXPECT_EQ(f.stats.max_radius, (std::vector<float>{4, 5, 2, 2}));
}

TEST(Densify, CloneSplitPruneWithMoments) {
  Fixture f;
  std::mt19937_64 rng(1);
  DensifyConfig cfg;
  const float extent = 2.f;  // clone if max scale <= 0.02
  DensifyResult r = densify_and_prune(f.m, f.adam, f.stats, cfg, extent, 0.f, rng);
  EXPECT_EQ(r.cloned, 1);
  EXPECT_EQ(r.split, 1);
  EXPECT_EQ(r.pruned, 1);
  // Rows: survivors 0, 2 (3 pruned), clone of 0, two children of 1.
  ASSERT_EQ(f.m.n, 5);
  float sh[5] = {0, 2, 0, 1, 1};
  float id[5] = {100, 102, 100, 101, 101};
  for (int i = 0; i < 5; ++i) {
    EXPECT_EQ(f.m.sh[i * 3], sh[i]) << i;
    EXPECT_EQ(f.m.extras[0].data[i * 2], id[i]) << i;
  }
  // Clone identical to its parent.
  for (int a = 0; a < 3; ++a) {
    EXPECT_EQ(f.m.mean[2 * 3 + a], f.m.mean[a]);
    EXPECT_EQ(f.m.log_scale[2 * 3 + a], f.m.log_scale[a]);
  }
  // Children: scale / 1.6, centres sampled near the parent (10, 11, 12) within a few sigma (0.5).
  for (int c = 3; c < 5; ++c)
    for (int a = 0; a < 3; ++a) {
      float parent_ls = std::log(0.5f) + (a == 1 ? std::log(0.5f) : 0.f);
      EXPECT_NEAR(f.m.log_scale[c * 3 + a], parent_ls - std::log(1.6f), 1e-6f);
      EXPECT_NEAR(f.m.mean[c * 3 + a], 10.f + a, 2.5f);
      EXPECT_NE(f.m.mean[c * 3 + a], 10.f + a);
    }
  EXPECT_NE(f.m.mean[3 * 3], f.m.mean[4 * 3]);
  // Moments: survivors keep theirs (Gaussian 0 -> 1, Gaussian 2 -> 3), new rows zero.
  for (auto& p : f.adam.params) {
    ASSERT_EQ(p.m.size(), 5u * p.dim) << p.name;
    float expect_m[5] = {1, 3, 0, 0, 0};
    for (int i = 0; i < 5; ++i) {
      EXPECT_EQ(p.m[i * p.dim], expect_m[i]) << p.name << " row " << i;
      EXPECT_EQ(p.v[i * p.dim + p.dim - 1], 2 * expect_m[i]) << p.name << " row " << i;
    }
  }
  EXPECT_EQ(f.stats.count, std::vector<int>(5, 0));
  EXPECT_EQ(f.stats.max_radius, std::vector<float>(5, 0.f));
}

TEST(Densify, ScreenAndWorldSizePruning) {
  Fixture f;
  f.stats.grad_accum.assign(4, 0.f);  // no densification
  std::mt19937_64 rng(1);
  DensifyConfig cfg;
  // Screen limit 3 px prunes 0 (radius 4) and 1 (radius 5; also world scale 0.5 > 0.1 x 2); 3 is transparent.
  DensifyResult r = densify_and_prune(f.m, f.adam, f.stats, cfg, 2.f, 3.f, rng);
  EXPECT_EQ(r.pruned, 3);
  ASSERT_EQ(f.m.n, 1);
  EXPECT_EQ(f.m.sh[0], 2.f);
  EXPECT_EQ(f.adam.get("quat").m, std::vector<float>(4, 3.f));
  // World size alone: limit large, extent small.
  Fixture g;
  g.stats.grad_accum.assign(4, 0.f);
  r = densify_and_prune(g.m, g.adam, g.stats, cfg, 0.04f, 1000.f, rng);  // 0.1 x 0.04 = 0.004 < 0.005
  EXPECT_EQ(g.m.n, 0);
}

TEST(Densify, PruneStepPrunesAsDensifyAndPruneWithoutGrowing) {
  // The fixture's Gaussians 0 and 1 would clone and split (densify_and_prune above); prune_step only prunes,
  // by the same rules.
  Fixture f;
  DensifyConfig cfg;
  DensifyResult r = prune_step(f.m, f.adam, f.stats, cfg, 2.f, 0.f);  // transparent only: Gaussian 3
  EXPECT_EQ(r.cloned + r.split, 0);
  EXPECT_EQ(r.pruned, 1);
  ASSERT_EQ(f.m.n, 3);
  EXPECT_EQ(f.m.sh[2 * 3], 2.f);
  EXPECT_EQ(f.stats.count, std::vector<int>(3, 0));
  Fixture g;
  r = prune_step(g.m, g.adam, g.stats, cfg, 2.f, 3.f);  // and by screen and world size: 0, 1 and 3
  EXPECT_EQ(r.pruned, 3);
  ASSERT_EQ(g.m.n, 1);
  EXPECT_EQ(g.m.sh[0], 2.f);
  EXPECT_EQ(g.adam.get("quat").m, std::vector<float>(4, 3.f));
}

TEST(Densify, OpacityReset) {
  Fixture f;
  reset_opacity(f.m, f.adam, 0.01f);
  EXPECT_NEAR(sigmoid(f.m.opacity_logit[0]), 0.01f, 1e-6f);
  EXPECT_NEAR(sigmoid(f.m.opacity_logit[3]), 0.001f, 1e-7f);  // below the cap: unchanged
  EXPECT_EQ(f.adam.get("opacity").m, std::vector<float>(4, 0.f));
  EXPECT_EQ(f.adam.get("opacity").v, std::vector<float>(4, 0.f));
  EXPECT_EQ(f.adam.get("mean").m[0], 1.f);
}

}  // namespace
}  // namespace hgs::train
