// bfloat16 products (src/nn/gemm_bf16.h) against brute-force references: the rounding itself, gemm_bf16 on
// rounded operands (only the float32 summation order may differ), and the bf16 linear layer and attention
// against their float32 versions within the bound that rounding both operands to 8 significant bits allows.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <random>
#include <vector>

#include "core/error.h"
#include "core/half.h"
#include "nn/gemm_bf16.h"
#include "nn/transformer.h"

namespace hgs::nn {
namespace {

std::vector<float> randn(size_t n, std::mt19937& rng, float scale = 1.f) {
  std::normal_distribution<float> d(0.f, scale);
  std::vector<float> v(n);
  for (float& x : v) x = d(rng);
  return v;
}

float from_bits(uint32_t u) {
  float f;
  std::memcpy(&f, &u, 4);
  return f;
}

uint16_t round1(float f) {
  uint16_t o;
  to_bf16(&f, 1, 1, 1, &o);
  return o;
}

TEST(GemmBf16, RoundsToNearestEvenAndKeepsSpecialValues) {
  EXPECT_EQ(round1(1.f), 0x3F80);
  // 1 + 2^-8 lies halfway between 1 and 1 + 2^-7: ties go to the even mantissa (1.0).
  EXPECT_EQ(round1(1.f + std::ldexp(1.f, -8)), 0x3F80);
  // 1 + 3 * 2^-8 is halfway between 1 + 2^-7 (odd) and 1 + 2^-6: up to the even one.
  EXPECT_EQ(round1(1.f + 3 * std::ldexp(1.f, -8)), 0x3F82);
  EXPECT_EQ(round1(from_bits(0x3F808001u)), 0x3F81);  // just above half: up
  EXPECT_EQ(round1(from_bits(0x3F807FFFu)), 0x3F80);  // just below half: down
  EXPECT_EQ(round1(-2.5f), 0xC020);
  EXPECT_EQ(round1(std::numeric_limits<float>::infinity()), 0x7F80);
  EXPECT_EQ(round1(-std::numeric_limits<float>::infinity()), 0xFF80);
  const uint16_t nan = round1(std::numeric_limits<float>::quiet_NaN());
  EXPECT_TRUE(std::isnan(bf16_to_float(nan)));
  EXPECT_TRUE(std::isnan(bf16_to_float(round1(from_bits(0x7F800001u)))));  // a NaN whose payload would carry
  EXPECT_EQ(round1(std::numeric_limits<float>::max()), 0x7F80);            // rounds up past the largest bf16
  // Every value: the result is one of the two neighbours and at most half a unit away.
  std::mt19937 rng(3);
  for (float x : randn(10000, rng, 100.f)) {
    const float r = bf16_to_float(round1(x));
    const float ulp = std::ldexp(1.f, std::ilogb(x) - 7);
    EXPECT_LE(std::fabs(r - x), 0.5f * ulp) << x;
  }
  // The scaled form rounds scale * x.
  const float x = 3.f;
  uint16_t o;
  to_bf16(&x, 1, 1, 1, &o, 0.5f);
  EXPECT_EQ(bf16_to_float(o), 1.5f);
}

// c = alpha * a op(b) + bias + beta * c by brute force in double on the bf16 operands.
void reference(int m, int n, int k, const std::vector<uint16_t>& a, int lda, const std::vector<uint16_t>& b, int ldb,
               bool trans_b, float alpha, const float* bias, float beta, std::vector<double>& c, int ldc,
               std::vector<double>& magnitude) {
  for (int i = 0; i < m; ++i)
    for (int j = 0; j < n; ++j) {
      double s = 0, mag = 0;
      for (int t = 0; t < k; ++t) {
        const double x = bf16_to_float(a[size_t(i) * lda + t]);
        const double y = bf16_to_float(trans_b ? b[size_t(j) * ldb + t] : b[size_t(t) * ldb + j]);
        s += x * y;
        mag += std::fabs(x * y);
      }
      double& o = c[size_t(i) * ldc + j];
      o = alpha * s + (bias ? bias[j] : 0.0) + beta * o;
      magnitude[size_t(i) * ldc + j] = std::fabs(alpha) * mag + (bias ? std::fabs(bias[j]) : 0.0) + std::fabs(beta * o);
    }
}

TEST(GemmBf16, MatchesBruteForceOnTheRoundedOperands) {
  std::mt19937 rng(7);
  struct Case {
    int m, n, k, pad_a, pad_b, pad_c;
    bool trans_b, bias;
    float alpha, beta;
  };
  const Case cases[] = {
      {1, 1, 1, 0, 0, 0, true, false, 1.f, 0.f},        {5, 7, 3, 0, 0, 0, false, false, 1.f, 0.f},
      {37, 19, 64, 3, 5, 2, true, true, 1.f, 0.f},      {64, 33, 100, 0, 7, 1, false, true, 0.125f, 0.f},
      {130, 70, 17, 9, 0, 4, true, false, 1.f, 1.f},    {16, 300, 256, 0, 0, 0, false, true, 1.f, 1.f},
      {200, 64, 4096, 0, 0, 0, true, false, 0.3f, 0.f}, {3, 4, 0, 0, 0, 0, true, true, 1.f, 1.f},  // empty sum
  };
  for (const Case& cs : cases) {
    const int lda = cs.k + cs.pad_a, ldb = (cs.trans_b ? cs.k : cs.n) + cs.pad_b, ldc = cs.n + cs.pad_c;
    const size_t b_rows = cs.trans_b ? cs.n : cs.k;
    std::vector<uint16_t> a = to_bf16(randn(size_t(cs.m) * lda, rng)), b = to_bf16(randn(b_rows * ldb, rng));
    std::vector<float> bias = randn(cs.n, rng), c = randn(size_t(cs.m) * ldc, rng);
    std::vector<double> ref(c.begin(), c.end()), mag(c.size());
    reference(cs.m, cs.n, cs.k, a, lda, b, ldb, cs.trans_b, cs.alpha, cs.bias ? bias.data() : nullptr, cs.beta, ref,
              ldc, mag);
    const std::vector<float> before = c;
    gemm_bf16(cs.m, cs.n, cs.k, a.data(), lda, b.data(), ldb, cs.trans_b, cs.alpha, cs.bias ? bias.data() : nullptr,
              cs.beta, c.data(), ldc);
    for (int i = 0; i < cs.m; ++i)
      for (int j = 0; j < ldc; ++j) {
        const size_t p = size_t(i) * ldc + j;
        if (j >= cs.n) {  // padding columns of c are never written
          EXPECT_EQ(c[p], before[p]);
          continue;
        }
        // float32 accumulation of k products: error <= k * 2^-24 * sum |terms| (a loose, order-free bound)
        EXPECT_NEAR(c[p], ref[p], (cs.k + 2) * 6e-8 * mag[p] + 1e-30) << cs.m << "x" << cs.n << "x" << cs.k;
      }
  }
}

TEST(GemmBf16, BetaMustBeZeroOrOne) {
  std::vector<uint16_t> a(4, 0x3F80);
  std::vector<float> c(4);
  EXPECT_THROW(gemm_bf16(2, 2, 2, a.data(), 2, a.data(), 2, true, 1.f, nullptr, 0.5f, c.data(), 2), Error);
}

// A bf16 product's error against float32: each operand is off by at most 2^-9 relatively, so each term by
// (1 + 2^-9)^2 - 1 < 2^-8 + 2^-18; the sum by that times the sum of |terms| (plus float32 summation).
double rounding_bound(const float* x, const float* w, int k) {
  double mag = 0;
  for (int t = 0; t < k; ++t) mag += std::fabs(double(x[t]) * w[t]);
  return mag * (std::ldexp(1.0, -8) + std::ldexp(1.0, -17) + k * 6e-8);
}

TEST(GemmBf16, LinearLayerWithinTheRoundingBoundOfFloat32) {
  std::mt19937 rng(11);
  for (int n : {13, 100}) {  // above nn::linear's few-row path (<= 12 rows stay float32)
    Linear l;
    l.in = 96, l.out = 40;
    l.w = randn(size_t(l.out) * l.in, rng, 0.1f);
    l.b = randn(l.out, rng);
    const std::vector<float> x = randn(size_t(n) * l.in, rng);
    std::vector<float> y32(size_t(n) * l.out), y16(y32.size()), acc16(y32.size(), 1.f), acc32(y32.size(), 1.f);
    linear(l, x.data(), n, y32.data());
    linear_add(l, x.data(), n, acc32.data());
    use_bf16(l);
    ASSERT_EQ(l.w16.size(), l.w.size());
    linear(l, x.data(), n, y16.data());
    linear_add(l, x.data(), n, acc16.data());
    double worst = 0;
    for (int i = 0; i < n; ++i)
      for (int o = 0; o < l.out; ++o) {
        const double bound = rounding_bound(x.data() + size_t(i) * l.in, l.w.data() + size_t(o) * l.in, l.in);
        const size_t p = size_t(i) * l.out + o;
        EXPECT_LE(std::fabs(y16[p] - y32[p]), bound);
        EXPECT_LE(std::fabs(acc16[p] - acc32[p]), bound + 1e-6);
        worst = std::max(worst, std::fabs(y16[p] - y32[p]) / bound);
      }
    EXPECT_GT(worst, 0.0) << "bf16 gave float32's exact results: the bf16 path did not run";
  }
}

TEST(GemmBf16, AttentionMatchesFloat32WithinBf16Accuracy) {
  std::mt19937 rng(5);
  const int nq = 20, nk = 33, heads = 3, hd = 16, w = heads * hd;
  const std::vector<float> q = randn(size_t(nq) * w, rng), k = randn(size_t(nk) * w, rng),
                           v = randn(size_t(nk) * w, rng);
  std::vector<float> out32(size_t(nq) * w), out16(out32.size()), scores(size_t(nq) * nk);
  const float scale = 0.25f;
  auto bias = [&](int h, float* s) {  // any additive term: the same in both
    for (int i = 0; i < nq * nk; ++i) s[i] += 0.01f * float((i * 7 + h) % 13);
  };
  multi_head_attention(q.data(), w, k.data(), w, v.data(), w, nq, nk, heads, hd, scale, out32.data(), w, scores.data(),
                       false, bias);
  std::vector<uint16_t> k16(size_t(nk) * w), v16(k16.size());
  split_heads_bf16(k.data(), nk, w, heads, hd, k16.data());
  split_heads_bf16(v.data(), nk, w, heads, hd, v16.data());
  // Split heads: head h's keys are contiguous [nk, hd].
  EXPECT_EQ(bf16_to_float(k16[size_t(1) * nk * hd + 2 * hd + 3]), bf16_to_float(round1(k[2 * w + hd + 3])));
  multi_head_attention_bf16(q.data(), w, k16.data(), v16.data(), nq, nk, heads, hd, scale, out16.data(), w,
                            scores.data(), false, bias);
  // Scores |q.k| * scale ~ 1 are off by ~2^-8 of their magnitude, probabilities by as much relatively, then
  // P V (values ~ 1) rounds again: a few 2^-8 in all. Outputs are means of values ~ N(0, 1).
  double worst = 0;
  for (size_t i = 0; i < out32.size(); ++i) worst = std::max(worst, double(std::fabs(out16[i] - out32[i])));
  EXPECT_LT(worst, 0.05);
  EXPECT_GT(worst, 0.0);
}

TEST(GemmBf16, ParsePrecision) {
  EXPECT_EQ(parse_precision("f32", "--precision"), Precision::F32);
  EXPECT_EQ(parse_precision("bf16", "--precision"), Precision::BF16);
  EXPECT_STREQ(precision_name(Precision::BF16), "bf16");
  try {
    parse_precision("f16", "--precision");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("--precision: unknown precision \"f16\""), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace hgs::nn
