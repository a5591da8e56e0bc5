// Semantic Contrastive Learning (paper eqs. 7-10).
//
// Pooling identity. The object-conditioned semantic render S_{u,k}(p) = sum_n q_{n,k} f_n alpha_n(p) T_n(p)
// (eq. 8) is only ever used mask-pooled (eq. 9), and pooling commutes with the sum over Gaussians:
//   z^pred_{u,k} = sum_p M_{u,k}(p) S_{u,k}(p) / (m + eps)
//                = sum_n q_{n,k} f_n [sum_p M_{u,k}(p) alpha_n(p) T_n(p)] / (m + eps)
//                = sum_n q_{n,k} f_n a_{n,k,u} / (m + eps),      m = sum_p M_{u,k}(p),
// so the rasterizer only accumulates one scalar a_{n,k,u} per Gaussian and object instead of rendering a
// D-channel image per object (tests/hybrid checks this against the direct render).
//
// InfoNCE (eq. 10). Anchor: the L2-normalised pooled prediction of object k in view u. Positive: the
// normalised reference z^ref_{v,k} of the same object in another view v that sees it; negatives: the
// references of the other foreground objects present in view v. sim = cosine, temperature tau2.
//   L = -log( exp(sim(a, r_k)/tau2) / sum_{k' in F_v} exp(sim(a, r_k')/tau2) )
#pragma once

#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <type_traits>
#include <vector>

#include "core/parallel.h"

namespace hgs::hybrid {

// P [J, D] = pooled predictions of objects objs[j] (column of q) with per-Gaussian weights a [N, J] and mask
// areas mass [J]. q [N, L], f [N, D].
template <class T>
void pooled_prediction(int n, int D, int L, int J, const T* q, const T* f, const T* a, const int* objs, const T* mass,
                       T eps, T* P);

// pooled_prediction with f_i read through an adder: make_adder() gives each chunk of Gaussians its own callable
// add(i, w, o, first) that adds w f_i to the partial row o [D], first = true at Gaussian i's first map (it may keep
// scratch and state: the calls of a chunk come from one thread, Gaussian by Gaussian in increasing i, a Gaussian's
// maps in increasing j), so that the embeddings can be stored in any format.
template <class T, class MakeAdder>
void pooled_prediction_add(int n, int D, int L, int J, const T* q, MakeAdder&& make_adder, const T* a, const int* objs,
                           const T* mass, T eps, T* P) {
  // A partial [J, D] per fixed chunk of Gaussians, added in chunk order: the same bits at any thread count.
  chunked_sum(FixedChunks(n, 1024, 64), size_t(J) * D, P, [&](long i0, long i1, T* part) {
    auto add = make_adder();
    for (long i = i0; i < i1; ++i) {
      bool first = true;
      for (int j = 0; j < J; ++j) {
        const T w = a[size_t(i) * J + j] * q[size_t(i) * L + objs[j]];
        if (w == T(0)) continue;  // most Gaussians do not touch most masks
        add(i, w, &part[size_t(j) * D], first);
        first = false;
      }
    }
  });
  for (int j = 0; j < J; ++j) {
    const T inv = T(1) / (mass[j] + eps);
    for (int d = 0; d < D; ++d) P[size_t(j) * D + d] *= inv;
  }
}

// pooled_prediction with the rows of f produced by row(i, buf) -> const T* [D] (which may widen a half-precision
// row into buf [D]), asked once per Gaussian that touches a mask.
template <class T, class RowFn>
void pooled_prediction_rows(int n, int D, int L, int J, const T* q, RowFn&& row, const T* a, const int* objs,
                            const T* mass, T eps, T* P) {
  auto make_adder = [&] {
    return [&row, D, buf = std::vector<T>(size_t(D)), fi = static_cast<const T*>(nullptr)](long i, T w, T* o,
                                                                                           bool first) mutable {
      if (first) fi = row(i, buf.data());
#pragma omp simd
      for (int d = 0; d < D; ++d) o[d] += w * fi[d];
    };
  };
  pooled_prediction_add(n, D, L, J, q, make_adder, a, objs, mass, eps, P);
}

// pooled_prediction of f stored as IEEE half rows fh [N, D] (the trainer's language embeddings): each row converted
// in registers as it is added, instead of widened into a float copy first (a store and a load of 2 KB a row at
// D = 512; about a fifth of the pass at one thread, BM_PooledPredictionHalf). The same values and sums as
// pooled_prediction_rows with ExtraGroup::row's widening, bit for bit: both form each w f + o as one fused
// multiply-add (the compiler contracts the other's loop; Scl.PooledPredictionHalfIsTheWidenedRowsBitwise).
inline void pooled_prediction_half(int n, int D, int L, int J, const float* q, const uint16_t* fh, const float* a,
                                   const int* objs, const float* mass, float eps, float* P) {
  auto make_adder = [&] {
    return [fh, D, N = size_t(n)](long i, float w, float* o, bool first) {
      const uint16_t* h = fh + size_t(i) * D;
      // As ExtraGroup::row: ask for the row two further on (rows are walked in increasing order).
      if (first && size_t(i) + 3 <= N)
        for (size_t b = 0; b < size_t(D) * 2; b += 64)
          __builtin_prefetch(reinterpret_cast<const char*>(h + 2 * size_t(D)) + b);
      const __m256 vw = _mm256_set1_ps(w);
      int d = 0;
      for (; d + 8 <= D; d += 8)
        _mm256_storeu_ps(o + d,
                         _mm256_fmadd_ps(vw, _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(h + d))),
                                         _mm256_loadu_ps(o + d)));
      for (; d < D; ++d) o[d] += w * _cvtsh_ss(h[d]);
    };
  };
  pooled_prediction_add(n, D, L, J, q, make_adder, a, objs, mass, eps, P);
}

// Backward of pooled_prediction: dP [J, D] -> dq [N, L] (added), df [N, D] (added), da [N, J] (overwritten);
// any of dq, df, da may be null to skip it. da is 0 where a = 0: such a Gaussian covers no pixel of the mask,
// so the rasterizer never reads that entry (its pixel-weighted-sum gradient only reaches pixels with M != 0).
template <class T>
void pooled_prediction_backward(int n, int D, int L, int J, const T* q, const T* f, const T* a, const int* objs,
                                const T* mass, T eps, const T* dP, T* dq, T* df, T* da);

// G = dP / (mass + eps): dP [J, D], mass [J] -> G [J, D], the per-object factor of every backward row below.
template <class T>
void pooled_row_factors(int J, int D, const T* dP, const T* mass, T eps, T* G) {
  for (int j = 0; j < J; ++j) {
    const T inv = T(1) / (mass[j] + eps);
    for (int d = 0; d < D; ++d) G[size_t(j) * D + d] = dP[size_t(j) * D + d] * inv;
  }
}

// Row i of pooled_prediction_backward's dq and da, for the trainer's pass over the Gaussians. fi = f_i [D];
// with G = dP / (mass + eps) [J, D]: da_i [J] (overwritten; 0 where a = 0), dq_i [L] (added). dq or da may be
// null. f's own gradient is pooled_df_row's (the trainer forms it at the step's end, over the step's views).
template <class T>
void pooled_backward_row(long i, int D, int L, int J, const T* q, const T* fi, const T* a, const int* objs, const T* G,
                         T* dq, T* da) {
  for (int j = 0; j < J; ++j) {
    const T ai = a[size_t(i) * J + j], qi = q[size_t(i) * L + objs[j]];
    if (ai == T(0)) {
      if (da) da[size_t(i) * J + j] = 0;
      continue;
    }
    const T* gj = G + size_t(j) * D;
    T dot = 0;
#pragma omp simd reduction(+ : dot)
    for (int d = 0; d < D; ++d) dot += fi[d] * gj[d];
    if (da) da[size_t(i) * J + j] = qi * dot;
    if (dq) dq[size_t(i) * L + objs[j]] += ai * dot;
  }
}

// Row i of pooled_prediction_backward's df: df_i = sum_j q_{i,objs[j]} a_{i,j} G_j [D], from row i's q_i [L] and
// a_i [J] (a row of one view's weight sums), added to df_i when `any` (else written). Returns whether df_i holds
// a term: false, leaving df_i unwritten, when every q a term is zero (the Gaussian touches none of the masks).
// A batched step adds its views' rows in view order.
template <class T>
bool pooled_df_row(int D, int J, const T* qi, const T* ai, const int* objs, const T* G, T* df_i, bool any) {
  for (int j = 0; j < J; ++j) {
    const T w = ai[j] * qi[objs[j]];
    if (ai[j] == T(0) || w == T(0)) continue;
    const T* gj = G + size_t(j) * D;
    if (!any) {
#pragma omp simd
      for (int d = 0; d < D; ++d) df_i[d] = w * gj[d];
      any = true;
    } else {
#pragma omp simd
      for (int d = 0; d < D; ++d) df_i[d] += w * gj[d];
    }
  }
  return any;
}

// InfoNCE of one anchor. p: unnormalised prediction [D]; refs: the candidates' unit reference vectors
// [R, D]; positive: index of the positive among them. dp (may be null) receives scale * dL/dp.
template <class T>
T info_nce(const T* p, int D, const T* refs, int R, int positive, T tau2, T* dp, T scale);

// Full-scene semantic loss of the no-SCL ablation: mean over the P pixels of 1 - cos(S(p), R(p)), where
// S(p) = the rendered language feature (sum_n f_n alpha T) at channel offset 0 of a pixel block of `stride`
// floats and R(p) the reference feature. Pixels where either is zero count 1 and pass no gradient.
// grad (may be null) receives scale * dL/dS added into [P, stride].
template <class T>
T cosine_loss(const T* S, int stride, const T* R, size_t P, int D, T* grad, T scale);

// cosine_loss with R produced one pixel at a time: ref(p, buf) returns R(p) [D], filling buf [D] (a thread's
// scratch) or pointing elsewhere; no [P, D] map is needed (the no-SCL ablation samples its feature grid per
// pixel). cosine_loss is this with ref = the rows of R: the same operations, the same bits.
template <class T, class RefRow>
T cosine_loss_rows(const T* S, int stride, RefRow&& ref, size_t P, int D, T* grad, T scale) {
  // Four pixels at a time: their twelve sums are independent chains (one pixel's three would wait on the adder's
  // latency), each still summed over d in order, so every pixel's values are those of a pixel-by-pixel loop.
  constexpr int kPix = 4;
  double loss = 0;
  const T g = scale / T(P);
  const size_t groups = (P + kPix - 1) / kPix;
#pragma omp parallel reduction(+ : loss)
  {
    std::vector<T> buf(static_cast<size_t>(kPix) * D);
#pragma omp for schedule(static)
    for (size_t q = 0; q < groups; ++q) {
      const size_t p0 = q * kPix;
      const int np = int(std::min<size_t>(kPix, P - p0));
      const T* s[kPix];
      const T* r[kPix];
      double ss[kPix] = {}, rr[kPix] = {}, sr[kPix] = {};
      for (int k = 0; k < np; ++k) {
        s[k] = S + (p0 + k) * stride;
        r[k] = ref(p0 + k, buf.data() + size_t(k) * D);
      }
      auto sums = [&](auto count) {  // count: kPix as a constant (the sums stay in registers), or the rest
        for (int d = 0; d < D; ++d)
          for (int k = 0; k < int(count); ++k) {
            ss[k] += double(s[k][d]) * s[k][d];
            rr[k] += double(r[k][d]) * r[k][d];
            sr[k] += double(s[k][d]) * r[k][d];
          }
      };
      if (np == kPix) sums(std::integral_constant<int, kPix>{});
      else sums(np);
      for (int k = 0; k < np; ++k) {
        if (ss[k] <= 1e-30 || rr[k] <= 1e-30) {
          loss += 1;
          continue;
        }
        const double ns = std::sqrt(ss[k]), nr = std::sqrt(rr[k]), c = sr[k] / (ns * nr);
        loss += 1 - c;
        if (grad) {
          T* gp = grad + (p0 + k) * stride;
          // d(1 - cos)/dS = -(R / (|S| |R|) - cos S / |S|^2)
          for (int d = 0; d < D; ++d) gp[d] += T(-double(g) * (r[k][d] / (ns * nr) - c * s[k][d] / ss[k]));
        }
      }
    }
  }
  return T(loss / double(P));
}

// L2-normalise v [D] in place; returns the norm before.
template <class T>
T normalize(T* v, int D);

}  // namespace hgs::hybrid
