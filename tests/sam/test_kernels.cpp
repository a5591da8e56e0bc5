// Kernels against brute-force double-precision evaluations: the ViT layers on a random model whose sizes
// exercise what the tiny fixture does not (a 28 x 28 grid in 5 x 5 windows of 6, padded to 30, and a global
// layer of 784 tokens split into blocks of query rows), and the decoder's reassociated cross attentions
// against plain attention.
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "nn/transformer.h"
#include "sam/decoder_attention.h"
#include "sam/model.h"
#include "sam_test_util.h"

namespace hgs::test {
namespace {

using sam::Linear;

std::vector<float> randn(size_t n, float s, std::mt19937& rng) {
  std::normal_distribution<float> d(0.f, s);
  std::vector<float> v(n);
  for (auto& x : v) x = d(rng);
  return v;
}
Linear lin(int out, int in, std::mt19937& rng) {
  return {in, out, randn(size_t(out) * in, 1.f / std::sqrt(float(in)), rng), randn(out, 0.2f, rng)};
}

using Mat = std::vector<double>;  // row-major

void ln(const sam::LayerNorm& l, const Mat& x, int n, int c, Mat& y) {
  y.resize(x.size());
  for (int i = 0; i < n; ++i) {
    double m = 0, v = 0;
    for (int j = 0; j < c; ++j) m += x[i * c + j];
    m /= c;
    for (int j = 0; j < c; ++j) v += (x[i * c + j] - m) * (x[i * c + j] - m);
    v /= c;
    for (int j = 0; j < c; ++j) y[i * c + j] = (x[i * c + j] - m) / std::sqrt(v + 1e-6) * l.g[j] + l.b[j];
  }
}
Mat apply(const Linear& l, const Mat& x, int n) {
  Mat y(size_t(n) * l.out);
  for (int i = 0; i < n; ++i)
    for (int o = 0; o < l.out; ++o) {
      double s = l.b[o];
      for (int k = 0; k < l.in; ++k) s += double(l.w[size_t(o) * l.in + k]) * x[size_t(i) * l.in + k];
      y[size_t(i) * l.out + o] = s;
    }
  return y;
}

// Attention of the tokens (y, x) of an s x s grid given by `pos` (grid cells, -1 = padding with zero input),
// straight from the formulas: scores q.k * scale + q.Rh[dy] + q.Rw[dx], softmax, values, proj.
void attend_window(const sam::VitLayer& l, int heads, int C, int s, const Mat& h, const std::vector<int>& cells,
                   Mat& out) {
  const int n = s * s, hd = C / heads;
  Mat in(size_t(n) * C, 0.0);
  for (int t = 0; t < n; ++t)
    if (cells[t] >= 0)
      for (int c = 0; c < C; ++c) in[size_t(t) * C + c] = h[size_t(cells[t]) * C + c];
  Mat qkv = apply(l.qkv, in, n), o(size_t(n) * C, 0.0);
  for (int hh = 0; hh < heads; ++hh)
    for (int i = 0; i < n; ++i) {
      std::vector<double> sc(n);
      double mx = -1e300;
      const double* q = &qkv[size_t(i) * 3 * C + hh * hd];
      for (int j = 0; j < n; ++j) {
        const double* k = &qkv[size_t(j) * 3 * C + C + hh * hd];
        double d = 0, rh = 0, rw = 0;
        const int dy = i / s - j / s + s - 1, dx = i % s - j % s + s - 1;
        for (int c = 0; c < hd; ++c) {
          d += q[c] * k[c];
          rh += q[c] * l.rel_h[size_t(dy) * hd + c];
          rw += q[c] * l.rel_w[size_t(dx) * hd + c];
        }
        sc[j] = d / std::sqrt(double(hd)) + rh + rw;
        mx = std::max(mx, sc[j]);
      }
      double sum = 0;
      for (auto& v : sc) sum += (v = std::exp(v - mx));
      for (int j = 0; j < n; ++j)
        for (int c = 0; c < hd; ++c)
          o[size_t(i) * C + hh * hd + c] += sc[j] / sum * qkv[size_t(j) * 3 * C + 2 * C + hh * hd + c];
    }
  Mat p = apply(l.proj, o, n);
  for (int t = 0; t < n; ++t)
    if (cells[t] >= 0)
      for (int c = 0; c < C; ++c) out[size_t(cells[t]) * C + c] += p[size_t(t) * C + c];
}

TEST(SamKernels, VitLayersMatchBruteForce) {
  std::mt19937 rng(11);
  const int g = 28, P = 2, C = 16, heads = 2, hd = C / heads, S = g * P, N = g * g;
  sam::SamModel m;
  sam::VisionEncoder& v = m.vision;
  v.patch = P, v.grid = g, v.hidden = C, v.heads = heads, v.out = 8;
  v.patch_embed = lin(C, 3 * P * P, rng);
  v.pos = randn(size_t(N) * C, 0.5f, rng);
  for (int window : {6, 0}) {
    sam::VitLayer l;
    l.window = window;
    const int size = window ? window : g;
    l.ln1 = {randn(C, 0.2f, rng), randn(C, 0.2f, rng)};
    for (auto& x : l.ln1.g) x += 1.f;
    l.ln2 = l.ln1;
    l.qkv = lin(3 * C, C, rng);
    l.proj = lin(C, C, rng);
    l.fc1 = lin(4 * C, C, rng);
    l.fc2 = lin(C, 4 * C, rng);
    l.rel_h = randn(size_t(2 * size - 1) * hd, 0.5f, rng);
    l.rel_w = randn(size_t(2 * size - 1) * hd, 0.5f, rng);
    v.layers.push_back(l);
  }
  v.neck1 = {C, 8, randn(size_t(8) * C, 0.3f, rng), std::vector<float>(8, 0.f)};
  v.neck2 = {72, 8, randn(size_t(8) * 72, 0.1f, rng), std::vector<float>(8, 0.f)};
  v.neck_ln1 = v.neck_ln2 = {std::vector<float>(8, 1.f), std::vector<float>(8, 0.f)};
  std::vector<float> img = randn(size_t(S) * S * 3, 1.f, rng);
  std::vector<std::vector<float>> stages;
  m.encode(img.data(), &stages);
  ASSERT_EQ(stages.size(), 3u);

  // Patch embedding.
  Mat x(size_t(N) * C);
  for (int py = 0; py < g; ++py)
    for (int px = 0; px < g; ++px)
      for (int o = 0; o < C; ++o) {
        double s = v.patch_embed.b[o] + v.pos[(size_t(py) * g + px) * C + o];
        for (int c = 0; c < 3; ++c)
          for (int ky = 0; ky < P; ++ky)
            for (int kx = 0; kx < P; ++kx)
              s += double(v.patch_embed.w[size_t(o) * 3 * P * P + (c * P + ky) * P + kx]) *
                   img[((size_t(py) * P + ky) * S + px * P + kx) * 3 + c];
        x[(size_t(py) * g + px) * C + o] = s;
      }
  EXPECT_LT(max_rel_err(stages[0], std::vector<float>(x.begin(), x.end())), 2e-6);
  for (size_t li = 0; li < v.layers.size(); ++li) {
    const sam::VitLayer& l = v.layers[li];
    Mat h;
    ln(l.ln1, x, N, C, h);
    const int s = l.window ? l.window : g, nw = (g + s - 1) / s;
    EXPECT_EQ(l.window ? nw * s : g, l.window ? 30 : 28);
    for (int wy = 0; wy < nw; ++wy)
      for (int wx = 0; wx < nw; ++wx) {
        std::vector<int> cells(size_t(s) * s, -1);
        for (int i = 0; i < s; ++i)
          for (int j = 0; j < s; ++j) {
            const int y = wy * s + i, xx = wx * s + j;
            if (y < g && xx < g) cells[size_t(i) * s + j] = y * g + xx;
          }
        attend_window(l, heads, C, s, h, cells, x);
      }
    ln(l.ln2, x, N, C, h);
    Mat a = apply(l.fc1, h, N);
    for (auto& t : a) t = 0.5 * t * (1 + std::erf(t / std::sqrt(2.0)));
    Mat b = apply(l.fc2, a, N);
    for (size_t i = 0; i < x.size(); ++i) x[i] += b[i];
    EXPECT_LT(max_rel_err(stages[li + 1], std::vector<float>(x.begin(), x.end())), 1e-5) << "layer " << li;
  }
}

}  // namespace
}  // namespace hgs::test

namespace hgs::test {
namespace {

// Plain attention in double: out [nq, C] = out_proj(concat_h softmax(q_h k_h^T / sqrt(d)) v_h), with q, k, v the
// projections of qin [nq, C], kin / vin [nk, C].
std::vector<float> plain_attention(const sam::Attention& a, int heads, const std::vector<float>& qin, int nq,
                                   const std::vector<float>& kin, const std::vector<float>& vin, int nk) {
  auto proj = [](const sam::Linear& l, const std::vector<float>& x, int n) {
    Mat xd(x.begin(), x.end());
    return apply(l, xd, n);
  };
  Mat q = proj(a.q, qin, nq), k = proj(a.k, kin, nk), v = proj(a.v, vin, nk);
  const int I = a.q.out, hd = I / heads;
  Mat o(size_t(nq) * I, 0.0);
  for (int h = 0; h < heads; ++h)
    for (int i = 0; i < nq; ++i) {
      std::vector<double> s(nk);
      double mx = -1e300, sum = 0;
      for (int j = 0; j < nk; ++j) {
        double d = 0;
        for (int c = 0; c < hd; ++c) d += q[size_t(i) * I + h * hd + c] * k[size_t(j) * I + h * hd + c];
        s[j] = d / std::sqrt(double(hd));
        mx = std::max(mx, s[j]);
      }
      for (auto& x : s) sum += (x = std::exp(x - mx));
      for (int j = 0; j < nk; ++j)
        for (int c = 0; c < hd; ++c) o[size_t(i) * I + h * hd + c] += s[j] / sum * v[size_t(j) * I + h * hd + c];
    }
  Mat out = apply(a.out, o, nq);
  return std::vector<float>(out.begin(), out.end());
}

TEST(SamKernels, ReassociatedDecoderAttentionMatchesPlainAttention) {
  std::mt19937 rng(5);
  const int C = 32, I = 16, heads = 4, few = 5, many = 300;
  sam::Attention a{lin(I, C, rng), lin(I, C, rng), lin(I, C, rng), lin(C, I, rng)};
  for (auto* l : {&a.q, &a.k})
    for (auto& x : l->w) x *= 3.f;  // peaked softmax
  std::vector<float> tok = randn(size_t(few) * C, 1.f, rng), img = randn(size_t(many) * C, 1.f, rng),
                     img2 = randn(size_t(many) * C, 1.f, rng), tok2 = randn(size_t(few) * C, 1.f, rng);
  sam::AttnWork w;
  // Tokens -> image (keys img, values img2).
  std::vector<float> out(size_t(few) * C);
  sam::attend_few_queries(a, heads, tok.data(), few, img.data(), img2.data(), many, out.data(), w);
  EXPECT_LT(max_rel_err(out, plain_attention(a, heads, tok, few, img, img2, many)), 2e-5);
  // Image -> tokens, with and without the precomputed query projection.
  std::vector<float> out2(size_t(many) * C), out3(size_t(many) * C), qp(size_t(many) * I);
  sam::attend_few_keys(a, heads, img.data(), nullptr, many, tok.data(), tok2.data(), few, out2.data(), w);
  const std::vector<float> ref = plain_attention(a, heads, img, many, tok, tok2, few);
  EXPECT_LT(max_rel_err(out2, ref), 2e-5);
  nn::linear(a.q, img.data(), many, qp.data());
  sam::attend_few_keys(a, heads, nullptr, qp.data(), many, tok.data(), tok2.data(), few, out3.data(), w);
  EXPECT_EQ(out3, out2);
}

}  // namespace
}  // namespace hgs::test
