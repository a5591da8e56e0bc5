// Reassociated decoder cross attentions: see decoder_attention.h.
#include "sam/decoder_attention.h"

#include <cblas.h>

#include <algorithm>
#include <cmath>

#include "nn/gemm_bf16.h"
#include "nn/thread_pool.h"
#include "nn/transformer.h"

namespace hgs::sam {

void attend_few_queries(const Attention& a, int heads, const float* qin, int nq, const float* xk, const float* xv,
                        int n, float* out, AttnWork& w, bool bf16, const uint16_t* xk16, const uint16_t* xv16) {
  const int C = a.q.in, I = a.q.out, hd = I / heads, R = heads * nq;
  const float scale = 1.f / std::sqrt(float(hd));
  w.q.resize(size_t(nq) * I);
  nn::linear(a.q, qin, nq, w.q.data());
  // qk [heads * nq, C]: row (h, i) = scale * Q_h[i] W_k[h rows]  (W_k [I, C])
  w.qk.resize(size_t(R) * C);
  for (int h = 0; h < heads; ++h)
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, nq, C, hd, scale, w.q.data() + h * hd, I,
                a.k.w.data() + size_t(h) * hd * C, C, 0.f, w.qk.data() + size_t(h) * nq * C, C);
  w.s.resize(size_t(R) * n);
  w.z.resize(size_t(R) * C);  // P X_v
  if (bf16) {
    w.a16.resize(size_t(R) * C);
    nn::convert_to_bf16_serial(w.qk.data(), R, C, C, w.a16.data());
    xk16 = nn::rounded_or_convert(xk16, xk, n, C, w.b16);
    nn::gemm_bf16(R, n, C, w.a16.data(), C, xk16, C, true, 1.f, nullptr, 0.f, w.s.data(), n);
    nn::softmax_rows(w.s.data(), R, n, false);
    w.a16.resize(size_t(R) * n);
    nn::convert_to_bf16_serial(w.s.data(), R, n, n, w.a16.data());
    xv16 = nn::rounded_or_convert(xv16, xv, n, C, w.c16);
    nn::gemm_bf16(R, C, n, w.a16.data(), n, xv16, C, false, 1.f, nullptr, 0.f, w.z.data(), C);
  } else {
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, R, n, C, 1.f, w.qk.data(), C, xk, C, 0.f, w.s.data(), n);
    nn::softmax_rows(w.s.data(), R, n, false);
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, R, C, n, 1.f, w.s.data(), n, xv, C, 0.f, w.z.data(), C);
  }
  // o [nq, I]: head h's columns = Z_h W_v[h rows]^T + b_v[h]
  w.o.resize(size_t(nq) * I);
  for (int h = 0; h < heads; ++h) {
    float* oh = w.o.data() + h * hd;
    for (int i = 0; i < nq; ++i)
      for (int j = 0; j < hd; ++j) oh[size_t(i) * I + j] = a.v.b[h * hd + j];
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, nq, hd, C, 1.f, w.z.data() + size_t(h) * nq * C, C,
                a.v.w.data() + size_t(h) * hd * C, C, 1.f, oh, I);
  }
  nn::linear(a.out, w.o.data(), nq, out);
}

void attend_few_keys(const Attention& a, int heads, const float* xq, const float* qproj, int n, const float* kin,
                     const float* vin, int nk, float* out, AttnWork& w, bool bf16) {
  const int C = a.q.in, I = a.q.out, hd = I / heads, R = heads * nk;
  const float scale = 1.f / std::sqrt(float(hd));
  if (!qproj) {
    w.q.resize(size_t(n) * I);
    nn::linear(a.q, xq, n, w.q.data());
    qproj = w.q.data();
  }
  w.k.resize(size_t(nk) * I);
  w.v.resize(size_t(nk) * I);
  nn::linear(a.k, kin, nk, w.k.data());
  nn::linear(a.v, vin, nk, w.v.data());
  // vo [heads * nk, C]: row (h, t) = V_h[t] W_o[:, h cols]^T  (W_o [C, I])
  w.vo.resize(size_t(R) * C);
  for (int h = 0; h < heads; ++h)
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, nk, C, hd, 1.f, w.v.data() + h * hd, I,
                a.out.w.data() + h * hd, I, 0.f, w.vo.data() + size_t(h) * nk * C, C);
  // s [n, heads * nk]: column block h = scale * Q_h K_h^T, softmax within each block
  // (A direct loop: per head a [n, hd] x [hd, nk] product with nk ~ 7, where OpenBLAS spent more time packing the
  // strided queries than multiplying.)
  w.s.resize(size_t(n) * R);
  for (int i = 0; i < n; ++i) {
    const float* qi = qproj + size_t(i) * I;
    float* si = w.s.data() + size_t(i) * R;
    for (int h = 0; h < heads; ++h)
      for (int t = 0; t < nk; ++t) {
        const float* kt = w.k.data() + size_t(t) * I + h * hd;
        float acc = 0.f;
#pragma omp simd reduction(+ : acc)
        for (int j = 0; j < hd; ++j) acc += qi[h * hd + j] * kt[j];
        si[h * nk + t] = scale * acc;
      }
  }
  nn::softmax_rows(w.s.data(), n * heads, nk, false);  // [n, heads, nk] = [n * heads, nk] row-major
  if (bf16) {
    w.a16.resize(size_t(n) * R);
    w.c16.resize(size_t(R) * C);
    nn::convert_to_bf16_serial(w.s.data(), n, R, R, w.a16.data());
    nn::convert_to_bf16_serial(w.vo.data(), R, C, C, w.c16.data());
    nn::gemm_bf16(n, C, R, w.a16.data(), R, w.c16.data(), C, false, 1.f, a.out.b.data(), 0.f, out, C);
  } else {
    for (int i = 0; i < n; ++i) std::copy(a.out.b.begin(), a.out.b.end(), out + size_t(i) * C);
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasNoTrans, n, C, R, 1.f, w.s.data(), R, w.vo.data(), C, 1.f, out, C);
  }
}

}  // namespace hgs::sam
