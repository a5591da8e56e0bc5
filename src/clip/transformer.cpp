// CLIP transformer block kernels: see transformer.h.
#include "clip/transformer.h"

#include "clip/fastmath.h"
#include "clip/thread_pool.h"

#include <cblas.h>

#include <algorithm>
#include <cmath>
#include <omp.h>

#include "core/error.h"

namespace hgs::clip {

void Workspace::reserve(int n, int width, int mlp_width, int max_len) {
  h.resize(size_t(n) * width);
  qkv.resize(size_t(n) * 3 * width);
  attn.resize(size_t(n) * width);
  mlp.resize(size_t(n) * mlp_width);
  scores.resize(size_t(max_len) * max_len);
}

namespace {

// y [n, out] (+)= x [n, in] W^T + b for a few rows: each weight row is streamed from memory once and dotted
// with every input row (memory-bound, like the weights themselves); rows of W are split over the thread pool.
// For n this small OpenBLAS's packing and thread hand-offs cost more than the arithmetic.
void linear_few_rows(const Linear& l, const float* x, int n, float* y, bool accumulate) {
  const int in = l.in, out = l.out;
  parallel_for(out, 64, [&](long r0, long r1) {
    for (long r = r0; r < r1; ++r) {
      const float* w = l.w.data() + size_t(r) * in;
      auto put = [&](int i, float s) {
        float& o = y[size_t(i) * out + r];
        o = (accumulate ? o : 0.f) + s + l.b[r];
      };
      int i = 0;
      for (; i + 4 <= n; i += 4) {  // four input rows per pass over the weight row
        const float *x0 = x + size_t(i) * in, *x1 = x0 + in, *x2 = x1 + in, *x3 = x2 + in;
        float s0 = 0.f, s1 = 0.f, s2 = 0.f, s3 = 0.f;
#pragma omp simd reduction(+ : s0, s1, s2, s3)
        for (int k = 0; k < in; ++k) {
          s0 += w[k] * x0[k];
          s1 += w[k] * x1[k];
          s2 += w[k] * x2[k];
          s3 += w[k] * x3[k];
        }
        put(i, s0), put(i + 1, s1), put(i + 2, s2), put(i + 3, s3);
      }
      for (; i < n; ++i) {
        const float* xi = x + size_t(i) * in;
        float s = 0.f;
#pragma omp simd reduction(+ : s)
        for (int k = 0; k < in; ++k) s += w[k] * xi[k];
        put(i, s);
      }
    }
  });
}

constexpr int kFewRows = 12;  // measured 2-4x faster than OpenBLAS up to 12 rows, on par at 16

}  // namespace

void linear(const Linear& l, const float* x, int n, float* y) {
  if (n <= 0) return;
  if (n <= kFewRows) return linear_few_rows(l, x, n, y, false);
  for (int i = 0; i < n; ++i) std::copy(l.b.begin(), l.b.end(), y + size_t(i) * l.out);
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, n, l.out, l.in, 1.f, x, l.in, l.w.data(), l.in, 1.f, y, l.out);
}

void linear_add(const Linear& l, const float* x, int n, float* y) {
  if (n <= 0) return;
  if (n <= kFewRows) return linear_few_rows(l, x, n, y, true);
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, n, l.out, l.in, 1.f, x, l.in, l.w.data(), l.in, 1.f, y, l.out);
  for (int i = 0; i < n; ++i) {
    float* r = y + size_t(i) * l.out;
    for (int j = 0; j < l.out; ++j) r[j] += l.b[j];
  }
}

void matmul(const float* x, int n, int k, const float* p, int n_out, float* y) {
  if (n <= 0) return;
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, n, n_out, k, 1.f, x, k, p, n_out, 0.f, y, n_out);
}

void layer_norm(const LayerNorm& ln, const float* x, int n, int c, float* y, float eps) {
  parallel_for(n, std::max(1, 32768 / std::max(c, 1)), [&](long r0, long r1) {
    for (long i = r0; i < r1; ++i) {
      const float* r = x + size_t(i) * c;
      float* o = y + size_t(i) * c;
      double mean = 0, var = 0;
      for (int j = 0; j < c; ++j) mean += r[j];
      mean /= c;
      for (int j = 0; j < c; ++j) var += (r[j] - mean) * (r[j] - mean);
      var /= c;
      const float m = float(mean), inv = float(1.0 / std::sqrt(var + eps));
      for (int j = 0; j < c; ++j) o[j] = (r[j] - m) * inv * ln.g[j] + ln.b[j];
    }
  });
}

void activation(Activation a, float* x, size_t count) {
  parallel_for(long(count), 65536, [&](long b, long e) {
    if (a == Activation::GELU) {
#pragma omp simd
      for (long i = b; i < e; ++i) x[i] = 0.5f * x[i] * (1.f + fast_erf(x[i] * 0.70710678118654752f));
    } else {
#pragma omp simd
      for (long i = b; i < e; ++i) x[i] = x[i] / (1.f + fast_exp(-1.702f * x[i]));
    }
  });
}

void softmax_rows(float* s, int rows, int cols, bool causal, int row0) {
  parallel_for(rows, std::max(1, 32768 / std::max(cols, 1)), [&](long r0, long r1) {
    for (long i = r0; i < r1; ++i) {
      float* r = s + size_t(i) * cols;
      const int m = causal ? std::min(cols, int(row0 + i + 1)) : cols;
      float mx = r[0];
#pragma omp simd reduction(max : mx)
      for (int j = 1; j < m; ++j) mx = std::max(mx, r[j]);
      float sum = 0;
#pragma omp simd reduction(+ : sum)
      for (int j = 0; j < m; ++j) {
        r[j] = fast_exp(r[j] - mx);
        sum += r[j];
      }
      const float inv = 1.f / sum;
#pragma omp simd
      for (int j = 0; j < m; ++j) r[j] *= inv;
      for (int j = m; j < cols; ++j) r[j] = 0.f;
    }
  });
}

void l2_normalize_rows(float* x, int n, int d) {
  for (int i = 0; i < n; ++i) {
    float* r = x + size_t(i) * d;
    double s = 0;
    for (int j = 0; j < d; ++j) s += double(r[j]) * r[j];
    const float inv = s > 0 ? float(1.0 / std::sqrt(s)) : 0.f;
    for (int j = 0; j < d; ++j) r[j] *= inv;
  }
}

void multi_head_attention(const float* q, int ldq, const float* k, int ldk, const float* v, int ldv, int nq, int nk,
                          int heads, int hd, float scale, float* out, int ldo, float* scores, bool causal,
                          const std::function<void(int, float*)>& bias) {
  for (int hh = 0; hh < heads; ++hh) {
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, nq, nk, hd, scale, q + hh * hd, ldq, k + hh * hd, ldk, 0.f,
                scores, nk);
    if (bias) bias(hh, scores);
    softmax_rows(scores, nq, nk, causal);
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, nq, hd, nk, 1.f, scores, nk, v + hh * hd, ldv, 0.f,
                out + hh * hd, ldo);
  }
}

void block_forward(const Block& b, int heads, Activation act, const std::vector<Segment>& segs, bool causal, float* x,
                   int n, Workspace& ws) {
  const int w = b.qkv.in, hd = w / heads, w3 = 3 * w;
  const float scale = 1.f / std::sqrt(float(hd));
  // Attention.
  layer_norm(b.ln1, x, n, w, ws.h.data());
  linear(b.qkv, ws.h.data(), n, ws.qkv.data());
  for (const Segment& sg : segs) {
    const float* base = ws.qkv.data() + size_t(sg.start) * w3;
    multi_head_attention(base, w3, base + w, w3, base + 2 * w, w3, sg.len, sg.len, heads, hd, scale,
                         ws.attn.data() + size_t(sg.start) * w, w, ws.scores.data(), causal);
  }
  linear_add(b.out, ws.attn.data(), n, x);
  // MLP.
  layer_norm(b.ln2, x, n, w, ws.h.data());
  linear(b.fc, ws.h.data(), n, ws.mlp.data());
  activation(act, ws.mlp.data(), size_t(n) * b.fc.out);
  linear_add(b.proj, ws.mlp.data(), n, x);
}

}  // namespace hgs::clip

namespace hgs::clip {

std::optional<Activation> parse_activation(const std::string& s) {
  if (s.empty() || s == "auto") return std::nullopt;
  if (s == "gelu") return Activation::GELU;
  if (s == "quick_gelu" || s == "quickgelu") return Activation::QuickGELU;
  fail("--act: unknown activation \"{}\" (auto, gelu or quick_gelu)", s);
}

void set_num_threads(int n) {
  if (n <= 0) return;
  openblas_set_num_threads(n);
  omp_set_num_threads(n);
}

}  // namespace hgs::clip
