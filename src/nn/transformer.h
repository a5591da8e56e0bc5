// Transformer kernels of the CLIP and SAM forwards, float32 on the CPU (bfloat16 products optional, gemm_bf16.h).
// All matrix products are cblas_sgemm calls on whole token matrices (OpenBLAS threads them); attention runs
// per sequence and head as two sgemm calls (Q K^T, then P V) with a row softmax in between. LayerNorm,
// activation and softmax are vectorised loops (fastmath.h) split over a blocking thread pool (thread_pool.h):
// OpenMP regions between the OpenBLAS calls made both thread pools spin against each other and halved the
// speed on 2 cores.
#pragma once
#include <cstddef>
#include <cstdint>
#include <functional>
#include <vector>

namespace hgs::nn {

enum class Activation { GELU, QuickGELU };  // x*Phi(x) (erf) and x*sigmoid(1.702x)

struct Linear {
  int in = 0, out = 0;
  std::vector<float> w;            // [out, in]
  std::vector<float> b;            // [out]
  std::vector<uint16_t> w16 = {};  // [out, in] w rounded to bfloat16 when the model runs in bf16, else empty
};

struct LayerNorm {
  std::vector<float> g, b;  // [width]
};

// y [N, out] = x [N, in] W^T + b. With l.w16 set (use_bf16), products of more than a few rows run in bfloat16
// (gemm_bf16.h: x rounded to bf16, float32 accumulation); otherwise float32 sgemm.
void linear(const Linear& l, const float* x, int n, float* y);
// y [N, out] += x [N, in] W^T + b.
void linear_add(const Linear& l, const float* x, int n, float* y);
// Rounds l.w to bfloat16 (l.w16) so that linear / linear_add run in bf16; l.w stays for few-row products.
void use_bf16(Linear& l);
// y [N, C] = LayerNorm(x [N, C]) with eps 1e-5 unless given (in place allowed).
void layer_norm(const LayerNorm& ln, const float* x, int n, int c, float* y, float eps = 1e-5f);
void activation(Activation a, float* x, size_t count);  // in place
void gelu_serial(float* x, long n);                     // GELU in place on the calling thread only
// Row-wise softmax of s [rows, cols]; with `causal`, row i keeps columns 0..row0+i only (others set to 0).
void softmax_rows(float* s, int rows, int cols, bool causal, int row0 = 0);

// Multi-head attention of one sequence: for every head h, out_h [nq, hd] = softmax(scale q_h k_h^T + B_h) v_h,
// where head h's q, k, v are the columns [h * hd, (h + 1) * hd) of q [nq, ldq], k [nk, ldk], v [nk, ldv] and its
// output goes to the same columns of out [nq, ldo]. Two sgemm calls per head around a row softmax over
// `scores` [nq, nk] (caller's buffer). `bias`, when given, adds B_h to the scaled scores [nq, nk] of head h
// before the softmax (SAM's relative positions); `causal` keeps key j <= query i only.
void multi_head_attention(const float* q, int ldq, const float* k, int ldk, const float* v, int ldv, int nq, int nk,
                          int heads, int hd, float scale, float* out, int ldo, float* scores, bool causal = false,
                          const std::function<void(int, float*)>& bias = {});

// The same attention with bfloat16 products (gemm_bf16.h): k and v already rounded to bf16 and split by head,
// [heads, nk, hd] each (split_heads_bf16; contiguous operands let oneDNN use its AMX kernels, strided ones
// measured 20x slower); the queries (unscaled, as `bias` may need them) and the softmax probabilities are
// rounded here, per head.
void multi_head_attention_bf16(const float* q, int ldq, const uint16_t* k, const uint16_t* v, int nq, int nk, int heads,
                               int hd, float scale, float* out, int ldo, float* scores, bool causal = false,
                               const std::function<void(int, float*)>& bias = {});

// x [N, n_out] = x [N, k] P for a projection matrix P [k, n_out].
void matmul(const float* x, int n, int k, const float* p, int n_out, float* y);

void l2_normalize_rows(float* x, int n, int d);

}  // namespace hgs::nn
