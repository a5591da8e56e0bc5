// Transformer kernels: see transformer.h.
#include "nn/transformer.h"

#include "nn/fastmath.h"
#include "nn/gemm_bf16.h"
#include "nn/thread_pool.h"

#include <cblas.h>

#include <algorithm>
#include <cmath>

namespace hgs::nn {

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

// y [n, out] (+)= bf16(x) [n, in] w16^T + b (gemm_bf16.h).
void linear_bf16(const Linear& l, const float* x, int n, float* y, bool accumulate) {
  thread_local std::vector<uint16_t> x16;
  x16.resize(size_t(n) * l.in);
  to_bf16(x, n, l.in, l.in, x16.data());
  gemm_bf16(n, l.out, l.in, x16.data(), l.in, l.w16.data(), l.in, true, 1.f, l.b.data(), accumulate ? 1.f : 0.f, y,
            l.out);
}

}  // namespace

void use_bf16(Linear& l) { l.w16 = to_bf16(l.w); }

void linear(const Linear& l, const float* x, int n, float* y) {
  if (n <= 0) return;
  if (n <= kFewRows) return linear_few_rows(l, x, n, y, false);
  if (!l.w16.empty()) return linear_bf16(l, x, n, y, false);
  for (int i = 0; i < n; ++i) std::copy(l.b.begin(), l.b.end(), y + size_t(i) * l.out);
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, n, l.out, l.in, 1.f, x, l.in, l.w.data(), l.in, 1.f, y, l.out);
}

void linear_add(const Linear& l, const float* x, int n, float* y) {
  if (n <= 0) return;
  if (n <= kFewRows) return linear_few_rows(l, x, n, y, true);
  if (!l.w16.empty()) return linear_bf16(l, x, n, y, true);
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

namespace {

// Rows [r0, r1) of LayerNorm: float sums (mean, then the centred variance) over the c channels.
HGS_AVX512_CLONE void layer_norm_rows(const float* x, long r0, long r1, int c, const float* g, const float* b,
                                      float eps, float* y) {
  for (long i = r0; i < r1; ++i) {
    const float* r = x + size_t(i) * c;
    float* o = y + size_t(i) * c;
    float sum = 0.f;
#pragma omp simd reduction(+ : sum)
    for (int j = 0; j < c; ++j) sum += r[j];
    const float m = sum / float(c);
    float var = 0.f;
#pragma omp simd reduction(+ : var)
    for (int j = 0; j < c; ++j) var += (r[j] - m) * (r[j] - m);
    const float inv = 1.f / std::sqrt(var / float(c) + eps);
#pragma omp simd
    for (int j = 0; j < c; ++j) o[j] = (r[j] - m) * inv * g[j] + b[j];
  }
}

HGS_AVX512_CLONE void gelu_range(float* x, long b, long e) {
#pragma omp simd
  for (long i = b; i < e; ++i) x[i] = 0.5f * x[i] * (1.f + fast_erf(x[i] * 0.70710678118654752f));
}

HGS_AVX512_CLONE void quick_gelu_range(float* x, long b, long e) {
#pragma omp simd
  for (long i = b; i < e; ++i) x[i] = x[i] / (1.f + fast_exp(-1.702f * x[i]));
}

// max of r[0, n), n >= 1. Written as a comparison: GCC vectorises this `reduction(max)` but leaves a
// std::max form scalar (one vmaxss per element, latency bound: 80 % of the softmax's time).
inline float row_max(const float* r, int n) {
  float mx = r[0];
#pragma omp simd reduction(max : mx)
  for (int j = 1; j < n; ++j) mx = r[j] > mx ? r[j] : mx;
  return mx;
}

HGS_AVX512_CLONE void softmax_row_range(float* s, long r0, long r1, int cols, bool causal, int row0) {
  for (long i = r0; i < r1; ++i) {
    float* r = s + size_t(i) * cols;
    const int m = causal ? std::min(cols, int(row0 + i + 1)) : cols;
    const float mx = row_max(r, m);
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
}

// Short rows (SAM's image-to-token attention: 7 keys per row): the exponentials of a whole block of rows in
// one vectorised pass over contiguous memory, the per-row maxima and sums as short scalar loops.
HGS_AVX512_CLONE void softmax_short_rows(float* s, long r0, long r1, int cols) {
  float* base = s + size_t(r0) * cols;
  for (long i = r0; i < r1; ++i) {
    float* r = s + size_t(i) * cols;
    float mx = r[0];
    for (int j = 1; j < cols; ++j) mx = r[j] > mx ? r[j] : mx;
    for (int j = 0; j < cols; ++j) r[j] -= mx;
  }
  const long total = (r1 - r0) * cols;
#pragma omp simd
  for (long k = 0; k < total; ++k) base[k] = fast_exp(base[k]);
  for (long i = r0; i < r1; ++i) {
    float* r = s + size_t(i) * cols;
    float sum = 0.f;
    for (int j = 0; j < cols; ++j) sum += r[j];
    const float inv = 1.f / sum;
    for (int j = 0; j < cols; ++j) r[j] *= inv;
  }
}

}  // namespace

void layer_norm(const LayerNorm& ln, const float* x, int n, int c, float* y, float eps) {
  parallel_for(n, std::max(1, 32768 / std::max(c, 1)),
               [&](long r0, long r1) { layer_norm_rows(x, r0, r1, c, ln.g.data(), ln.b.data(), eps, y); });
}

void gelu_serial(float* x, long n) { gelu_range(x, 0, n); }

void activation(Activation a, float* x, size_t count) {
  parallel_for(long(count), 65536, [&](long b, long e) {
    if (a == Activation::GELU) gelu_range(x, b, e);
    else quick_gelu_range(x, b, e);
  });
}

void softmax_rows(float* s, int rows, int cols, bool causal, int row0) {
  if (cols < 16 && !causal)
    return parallel_for(rows, std::max(1, 32768 / std::max(cols, 1)),
                        [&](long r0, long r1) { softmax_short_rows(s, r0, r1, cols); });
  parallel_for(rows, std::max(1, 32768 / std::max(cols, 1)),
               [&](long r0, long r1) { softmax_row_range(s, r0, r1, cols, causal, row0); });
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

void multi_head_attention_bf16(const float* q, int ldq, const uint16_t* k, const uint16_t* v, int nq, int nk, int heads,
                               int hd, float scale, float* out, int ldo, float* scores, bool causal,
                               const std::function<void(int, float*)>& bias) {
  thread_local std::vector<uint16_t> q16, p16;
  thread_local std::vector<float> o;
  q16.resize(size_t(nq) * hd);
  p16.resize(size_t(nq) * nk);
  o.resize(size_t(nq) * hd);
  for (int hh = 0; hh < heads; ++hh) {
    const size_t head = size_t(hh) * nk * hd;
    convert_to_bf16_serial(q + hh * hd, nq, hd, ldq, q16.data());
    gemm_bf16(nq, nk, hd, q16.data(), hd, k + head, hd, true, scale, nullptr, 0.f, scores, nk);
    if (bias) bias(hh, scores);
    softmax_rows(scores, nq, nk, causal);
    convert_to_bf16_serial(scores, nq, nk, nk, p16.data());
    gemm_bf16(nq, hd, nk, p16.data(), nk, v + head, hd, false, 1.f, nullptr, 0.f, o.data(), hd);
    for (int i = 0; i < nq; ++i) std::copy_n(o.data() + size_t(i) * hd, hd, out + size_t(i) * ldo + hh * hd);
  }
}

}  // namespace hgs::nn
