// The mask decoder's cross attentions between a few prompt tokens (T ~ 7) and many image tokens (N = 4096),
// reassociated so that no [N, C] x [C, inner] projection of the image tokens is needed per prompt:
//   few queries (tokens -> image): scores_h = (Q_h W_k,h) X_k^T (the dropped Q_h . b_k,h is the same for every
//     key, so the softmax ignores it); out_h = (P_h X_v) W_v,h^T + b_v,h (rows of P sum to 1). All heads are
//     stacked into single sgemm calls: [heads * T, C] x [C, N] and [heads * T, N] x [N, C].
//   few keys (image -> tokens): out = sum_h P_h (V_h W_o,h^T) + b_o, one [N, heads * T] x [heads * T, C] sgemm
//     instead of the [N, inner] x [inner, C] output projection; the queries' projection may be given
//     precomputed (the first block's image tokens are the same for every prompt).
// Mathematically the same attention as q/k/v projections, per-head softmax(q k^T / sqrt(d)) v and out_proj;
// float rounding differs.
#pragma once
#include <vector>

#include "sam/model.h"

namespace hgs::sam {

struct AttnWork {
  std::vector<float> q, k, v, qk, s, z, o, vo;
  std::vector<uint16_t> a16, b16, c16;  // operands rounded to bfloat16 (bf16 = true)
};

// out [nq, C] = attention(qin [nq, C] -> keys xk [n, C], values xv [n, C]), nq small. With `bf16`, the two
// products over the n image tokens run in bfloat16 (nn/gemm_bf16.h; xk, xv and the scores rounded).
// xk16 / xv16 (optional, bf16 only): xk and xv already rounded, [n, C] each (the caller shares them between
// products); xk / xv may then be null.
void attend_few_queries(const Attention& a, int heads, const float* qin, int nq, const float* xk, const float* xv,
                        int n, float* out, AttnWork& w, bool bf16 = false, const uint16_t* xk16 = nullptr,
                        const uint16_t* xv16 = nullptr);

// out [n, C] = attention(queries xq [n, C] -> kin [nk, C], vin [nk, C]), nk small; `qproj` [n, inner] is
// q_proj(xq) when already computed (else nullptr). With `bf16`, the product of the probabilities with the
// projected values runs in bfloat16 (the q projection follows a.q's own precision).
void attend_few_keys(const Attention& a, int heads, const float* xq, const float* qproj, int n, const float* kin,
                     const float* vin, int nk, float* out, AttnWork& w, bool bf16 = false);

}  // namespace hgs::sam
