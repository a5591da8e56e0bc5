// SAM's mask decoder: a two-way transformer between the prompt tokens [iou token, mask tokens, sparse prompt]
// and the image tokens (embedding + no-mask embedding, with the dense positional encoding added to queries and
// keys at every attention), then output upscaling (two 2x2 stride-2 transposed convolutions, channel LayerNorm
// and GELU), one hypernetwork MLP per mask token giving the weights of a dot product with every upscaled pixel,
// and the IoU head on the IoU token.
//   block (first block without the token residual and positions in self-attention):
//     q = LN1(q + self(q + qpe, q + qpe, q)); q = LN2(q + t2i(q + qpe, k + kpe, k)); q = LN3(q + mlp(q));
//     k = LN4(k + i2t(k + kpe, q + qpe, q));   final: q = LN(q + t2i_final(q + qpe, k + kpe, k)).
// Attention projects to an inner width (C / 2 in the cross attentions), splits heads, scales by 1/sqrt(head dim).
// The first block's token-to-image keys and values and image-to-token queries depend on the image only and are
// computed once per call; the other cross attentions use the reassociated forms of decoder_attention.h.
#include <cblas.h>
#include <omp.h>
#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "nn/thread_pool.h"
#include "nn/transformer.h"
#include "sam/decoder_attention.h"
#include "sam/model.h"

namespace hgs::sam {
namespace {

struct Proj {
  std::vector<float> q, k, v, o;
};

// One thread's buffers for SamModel::decode.
struct Work {
  Proj w;
  AttnWork aw;
  std::vector<float> scores, q, qpe, keys, tmp, qq, kk, mlp, y, u1, u2, qproj;
  std::vector<uint16_t> x16, kk16, keys16;  // bf16: keys + pe and keys rounded once for all their products
};

void add(const float* a, const float* b, size_t n, std::vector<float>& out) {
  out.resize(n);
  for (size_t i = 0; i < n; ++i) out[i] = a[i] + b[i];
}

// out [nq, C] = attention(qin [nq, C], kin [nk, C], vin [nk, C]); `kv` (optional) holds k_proj(kin) and
// v_proj(vin) already computed.
void attend(const Attention& a, int heads, const float* qin, int nq, const float* kin, const float* vin, int nk,
            float* out, Proj& w, std::vector<float>& scores, const Proj* kv = nullptr) {
  const int I = a.q.out, hd = I / heads;
  w.q.resize(size_t(nq) * I);
  nn::linear(a.q, qin, nq, w.q.data());
  const float *K, *V;
  if (kv) {
    K = kv->k.data();
    V = kv->v.data();
  } else {
    w.k.resize(size_t(nk) * I);
    w.v.resize(size_t(nk) * I);
    nn::linear(a.k, kin, nk, w.k.data());
    nn::linear(a.v, vin, nk, w.v.data());
    K = w.k.data();
    V = w.v.data();
  }
  w.o.resize(size_t(nq) * I);
  scores.resize(size_t(nq) * nk);
  nn::multi_head_attention(w.q.data(), I, K, I, V, I, nq, nk, heads, hd, 1.f / std::sqrt(float(hd)), w.o.data(), I,
                           scores.data());
  nn::linear(a.out, w.o.data(), nq, out);
}

void relu(float* x, size_t n) {
  for (size_t i = 0; i < n; ++i) x[i] = std::max(x[i], 0.f);
}

// y [out] = mlp(x [in]) for one vector.
std::vector<float> run_mlp(const Mlp& m, const float* x) {
  std::vector<float> a(x, x + m.layers.front().in), b;
  for (size_t j = 0; j < m.layers.size(); ++j) {
    b.resize(m.layers[j].out);
    nn::linear(m.layers[j], a.data(), 1, b.data());
    if (j + 1 < m.layers.size()) relu(b.data(), b.size());
    a.swap(b);
  }
  return a;
}

// out [2g, 2g, u.out] = the 2x2 stride-2 transposed convolution of x [g, g, u.in] as one product with
// u.w [in, 4 out] into y [g * g, 4 out] (in bfloat16 when u.w16 is set, on the calling thread: the decoder
// runs one prompt per thread). Buffers are the caller's, reused from prompt to prompt: allocating them per
// prompt cost page faults and zeroing (~15 % of a batch).
// `rounded` (optional, bf16): x already rounded to bf16.
void upconv(const Upconv& u, const float* x, int g, std::vector<float>& y, std::vector<uint16_t>& x16,
            std::vector<float>& out, const uint16_t* rounded = nullptr) {
  y.resize(size_t(g) * g * 4 * u.out);
  out.resize(size_t(4) * g * g * u.out);
  if (!u.w16.empty()) {
    rounded = nn::rounded_or_convert(rounded, x, g * g, u.in, x16);
    nn::gemm_bf16(g * g, 4 * u.out, u.in, rounded, u.in, u.w16.data(), 4 * u.out, false, 1.f, nullptr, 0.f, y.data(),
                  4 * u.out);
  } else {
    nn::matmul(x, g * g, u.in, u.w.data(), 4 * u.out, y.data());
  }
  const int G = 2 * g;
  for (int i = 0; i < g; ++i)
    for (int j = 0; j < g; ++j)
      for (int d = 0; d < 4; ++d) {
        const float* s = y.data() + (size_t(i) * g + j) * 4 * u.out + d * u.out;
        float* o = out.data() + (size_t(2 * i + d / 2) * G + 2 * j + d % 2) * u.out;
        for (int c = 0; c < u.out; ++c) o[c] = s[c] + u.b[c];
      }
}

// What every prompt of one decode call shares, computed from the image only: the dense positional encoding pe
// [N, C], the image tokens src0 [N, C] (embedding + no-mask embedding), the first block's token-to-image keys and
// values (kv0; bf16: split by head and rounded once, k0_16 / v0_16) and its image-to-token query projection q0.
struct ImageSide {
  int C = 0, g = 0, N = 0, heads = 0, Tt = 0;  // channels, grid, image tokens, heads, prompt-side tokens
  bool bf16 = false;
  int I0 = 0, hd0 = 0;  // the first token-to-image attention's inner width and head dim
  std::vector<float> pe, src0, q0;
  Proj kv0;
  std::vector<uint16_t> k0_16, v0_16;
};

ImageSide image_side(const SamModel& m, const float* emb, int T) {
  const MaskDecoder& d = m.decoder;
  ImageSide s;
  s.C = m.channels();
  s.g = m.vision.grid;
  s.N = s.g * s.g;
  s.heads = d.heads;
  s.Tt = 1 + d.tokens + T;  // iou token, mask tokens, prompt tokens
  const int C = s.C, N = s.N;
  s.pe = m.dense_pe();
  s.src0.resize(size_t(N) * C);
  std::vector<float> kpe(size_t(N) * C);
  nn::parallel_for(N, 64, [&](long t0, long t1) {  // image tokens on the pool (serial, they capped the scaling)
    for (size_t i = size_t(t0) * C; i < size_t(t1) * C; ++i) {
      s.src0[i] = emb[i] + m.prompt.no_mask[i % C];
      kpe[i] = s.src0[i] + s.pe[i];
    }
  });
  const Attention& a0 = d.layers[0].token_to_image;
  s.kv0.k.resize(size_t(N) * a0.k.out);
  s.kv0.v.resize(size_t(N) * a0.v.out);
  nn::linear(a0.k, kpe.data(), N, s.kv0.k.data());
  nn::linear(a0.v, s.src0.data(), N, s.kv0.v.data());
  const Attention& i0 = d.layers[0].image_to_token;
  s.q0.resize(size_t(N) * i0.q.out);
  nn::linear(i0.q, kpe.data(), N, s.q0.data());
  s.bf16 = m.precision == nn::Precision::BF16;
  s.I0 = a0.q.out;
  s.hd0 = s.I0 / s.heads;
  if (s.bf16) {  // for multi_head_attention_bf16
    s.k0_16.resize(size_t(N) * s.I0);
    s.v0_16.resize(size_t(N) * s.I0);
    nn::split_heads_bf16(s.kv0.k.data(), N, s.I0, s.heads, s.hd0, s.k0_16.data());
    nn::split_heads_bf16(s.kv0.v.data(), N, s.I0, s.heads, s.hd0, s.v0_16.data());
  }
  return s;
}

// The image operands of a token-to-image attention from the current keys: kk = keys + pe (f32), or kk16 and
// keys16 (bf16).
void image_operands(const ImageSide& s, Work& wk) {
  if (s.bf16) {
    wk.kk16.resize(wk.keys.size());
    wk.keys16.resize(wk.keys.size());
    nn::sum_to_bf16_serial(wk.keys.data(), s.pe.data(), wk.keys.size(), wk.kk16.data());
    nn::convert_to_bf16_serial(wk.keys.data(), s.N, s.C, s.C, wk.keys16.data());
  } else {
    add(wk.keys.data(), s.pe.data(), wk.keys.size(), wk.kk);
  }
}

// q = LN1(q + self(q + qpe, q + qpe, q)); the first block: q = LN1(self(q, q, q)).
void layer_self_attention(const MaskDecoder& d, const TwoWayLayer& l, bool first, const ImageSide& s, Work& wk) {
  std::vector<float>& q = wk.q;
  if (first) {
    attend(l.self_attn, s.heads, q.data(), s.Tt, q.data(), q.data(), s.Tt, wk.tmp.data(), wk.w, wk.scores);
    std::copy_n(wk.tmp.data(), size_t(s.Tt) * s.C, q.data());
  } else {
    add(q.data(), wk.qpe.data(), q.size(), wk.qq);
    attend(l.self_attn, s.heads, wk.qq.data(), s.Tt, wk.qq.data(), q.data(), s.Tt, wk.tmp.data(), wk.w, wk.scores);
    for (size_t i = 0; i < q.size(); ++i) q[i] += wk.tmp[i];
  }
  nn::layer_norm(l.ln1, q.data(), s.Tt, s.C, q.data(), d.ln_eps);
}

// q = LN2(q + t2i(q + qpe, k + kpe, k)): the first block from the precomputed keys and values, the others
// reassociated (attend_few_queries).
void layer_token_to_image(const MaskDecoder& d, const TwoWayLayer& l, bool first, const ImageSide& s, Work& wk) {
  std::vector<float>& q = wk.q;
  add(q.data(), wk.qpe.data(), q.size(), wk.qq);
  if (first && s.bf16) {
    const Attention& a = l.token_to_image;
    Proj& w = wk.w;
    w.q.resize(size_t(s.Tt) * s.I0);
    w.o.resize(size_t(s.Tt) * s.I0);
    wk.scores.resize(size_t(s.Tt) * s.N);
    nn::linear(a.q, wk.qq.data(), s.Tt, w.q.data());
    nn::multi_head_attention_bf16(w.q.data(), s.I0, s.k0_16.data(), s.v0_16.data(), s.Tt, s.N, s.heads, s.hd0,
                                  1.f / std::sqrt(float(s.hd0)), w.o.data(), s.I0, wk.scores.data());
    nn::linear(a.out, w.o.data(), s.Tt, wk.tmp.data());
  } else if (first) {
    attend(l.token_to_image, s.heads, wk.qq.data(), s.Tt, nullptr, nullptr, s.N, wk.tmp.data(), wk.w, wk.scores,
           &s.kv0);
  } else {
    image_operands(s, wk);
    attend_few_queries(l.token_to_image, s.heads, wk.qq.data(), s.Tt, wk.kk.data(), wk.keys.data(), s.N, wk.tmp.data(),
                       wk.aw, s.bf16, wk.kk16.data(), wk.keys16.data());
  }
  for (size_t i = 0; i < q.size(); ++i) q[i] += wk.tmp[i];
  nn::layer_norm(l.ln2, q.data(), s.Tt, s.C, q.data(), d.ln_eps);
}

// q = LN3(q + mlp(q)).
void layer_mlp(const MaskDecoder& d, const TwoWayLayer& l, const ImageSide& s, Work& wk) {
  wk.mlp.resize(size_t(s.Tt) * l.mlp1.out);
  nn::linear(l.mlp1, wk.q.data(), s.Tt, wk.mlp.data());
  relu(wk.mlp.data(), wk.mlp.size());
  nn::linear_add(l.mlp2, wk.mlp.data(), s.Tt, wk.q.data());
  nn::layer_norm(l.ln3, wk.q.data(), s.Tt, s.C, wk.q.data(), d.ln_eps);
}

// k = LN4(k + i2t(k + kpe, q + qpe, q)), the queries projected once per call for the first block; kk = keys + pe
// is still current in the others (the token-to-image attention changed the tokens only).
void layer_image_to_token(const MaskDecoder& d, const TwoWayLayer& l, bool first, const ImageSide& s, Work& wk) {
  add(wk.q.data(), wk.qpe.data(), wk.q.size(), wk.qq);
  const float* qp = first ? s.q0.data() : nullptr;
  if (!first && s.bf16) {  // the query projection from the rounded kk16 of the token-to-image attention
    const Linear& lq = l.image_to_token.q;
    wk.qproj.resize(size_t(s.N) * lq.out);
    nn::gemm_bf16(s.N, lq.out, s.C, wk.kk16.data(), s.C, lq.w16.data(), s.C, true, 1.f, lq.b.data(), 0.f,
                  wk.qproj.data(), lq.out);
    qp = wk.qproj.data();
  }
  attend_few_keys(l.image_to_token, s.heads, qp ? nullptr : wk.kk.data(), qp, s.N, wk.qq.data(), wk.q.data(), s.Tt,
                  wk.tmp.data(), wk.aw, s.bf16);
  for (size_t i = 0; i < wk.keys.size(); ++i) wk.keys[i] += wk.tmp[i];
  nn::layer_norm(l.ln4, wk.keys.data(), s.N, s.C, wk.keys.data(), d.ln_eps);
}

// The hypernetwork weights hyper [tokens, D]: one MLP per mask token on its output token (q [Tt, C]).
std::vector<float> hyper_weights(const MaskDecoder& d, const float* q, int C, int D) {
  std::vector<float> hyper(size_t(d.tokens) * D);
  for (int t = 0; t < d.tokens; ++t) {
    std::vector<float> h = run_mlp(d.hyper[t], q + size_t(1 + t) * C);
    if (int(h.size()) != D) fail("SAM hypernetwork {} gives {} values, the upscaled embedding has {}", t, h.size(), D);
    std::copy(h.begin(), h.end(), hyper.begin() + size_t(t) * D);
  }
  return hyper;
}

// masks [tokens, P] = hyper [tokens, D] x GELU(u2)^T [D, P] (u2 [P, D], GELU applied in place), the GELU and the
// dot products of a block of pixels in one pass while the block is in cache (a separate GELU pass and sgemm read
// u2 twice).
void mask_logits(const float* hyper, int tokens, int D, int P, float* u2, float* masks) {
  constexpr int kBlock = 128;
  for (int p0 = 0; p0 < P; p0 += kBlock) {
    const int np = std::min(kBlock, P - p0);
    float* px = u2 + size_t(p0) * D;
    nn::gelu_serial(px, long(np) * D);
    for (int t = 0; t < tokens; ++t) {
      const float* h = hyper + size_t(t) * D;
      float* o = masks + size_t(t) * P + p0;
      for (int i = 0; i < np; ++i) {
        const float* x = px + size_t(i) * D;
        float acc = 0.f;
#pragma omp simd reduction(+ : acc)
        for (int c = 0; c < D; ++c) acc += h[c] * x[c];
        o[i] = acc;
      }
    }
  }
}

// The heads on the transformer's output (tokens wk.q, image tokens wk.keys): upscaling [g, g, C] -> [2g, 2g,
// C/4] (LN, GELU) -> [4g, 4g, C/8] (GELU), the mask logits of every mask token and the IoU head.
void predict_masks(const MaskDecoder& d, const ImageSide& s, Work& wk, Prediction& r) {
  const int g = s.g;
  upconv(d.up1, wk.keys.data(), g, wk.y, wk.x16, wk.u1, s.bf16 ? wk.keys16.data() : nullptr);  // keys16 current
  nn::layer_norm(d.up_ln, wk.u1.data(), 4 * s.N, d.up1.out, wk.u1.data(), 1e-6f);
  nn::activation(nn::Activation::GELU, wk.u1.data(), wk.u1.size());
  upconv(d.up2, wk.u1.data(), 2 * g, wk.y, wk.x16, wk.u2);
  const int D = d.up2.out, P = 16 * s.N;
  const std::vector<float> hyper = hyper_weights(d, wk.q.data(), s.C, D);
  r.tokens = d.tokens;
  r.size = 4 * g;
  r.lowres.resize(size_t(d.tokens) * P);
  mask_logits(hyper.data(), d.tokens, D, P, wk.u2.data(), r.lowres.data());
  r.iou = run_mlp(d.iou_head, wk.q.data());
}

// One prompt, sparse [T, C]: the tokens [iou token, mask tokens, prompt], the two-way blocks, the final
// token-to-image attention, then the heads.
void decode_prompt(const MaskDecoder& d, const ImageSide& s, const float* sparse, int T, Work& wk, Prediction& r) {
  const int C = s.C;
  std::vector<float>& q = wk.q;
  q.resize(size_t(s.Tt) * C);
  std::copy(d.iou_token.begin(), d.iou_token.end(), q.begin());
  std::copy(d.mask_tokens.begin(), d.mask_tokens.end(), q.begin() + C);
  std::copy_n(sparse, size_t(T) * C, q.begin() + size_t(1 + d.tokens) * C);
  wk.qpe = q;
  wk.keys = s.src0;
  wk.tmp.resize(std::max(size_t(s.Tt), size_t(s.N)) * C);
  for (size_t li = 0; li < d.layers.size(); ++li) {
    const TwoWayLayer& l = d.layers[li];
    layer_self_attention(d, l, li == 0, s, wk);
    layer_token_to_image(d, l, li == 0, s, wk);
    layer_mlp(d, l, s, wk);
    layer_image_to_token(d, l, li == 0, s, wk);
  }
  add(q.data(), wk.qpe.data(), q.size(), wk.qq);
  image_operands(s, wk);
  attend_few_queries(d.final_attn, s.heads, wk.qq.data(), s.Tt, wk.kk.data(), wk.keys.data(), s.N, wk.tmp.data(), wk.aw,
                     s.bf16, wk.kk16.data(), wk.keys16.data());
  for (size_t i = 0; i < q.size(); ++i) q[i] += wk.tmp[i];
  nn::layer_norm(d.ln_final, q.data(), s.Tt, C, q.data(), d.ln_final_eps);
  predict_masks(d, s, wk, r);
}

}  // namespace

std::vector<Prediction> SamModel::decode(const float* emb, const float* sparse, int B, int T) const {
  const MaskDecoder& d = decoder;
  if (d.layers.empty()) fail("SAM mask decoder has no layers");
  const ImageSide s = image_side(*this, emb, T);
  std::vector<Prediction> res(B);
  // Several prompts: one prompt per thread with single-threaded OpenBLAS (one hand-off per batch instead of one
  // per matrix product; on a shared machine the per-call thread hand-offs cost more than the products).
  const bool per_prompt = B > 1 && nn::pool_threads() > 1;
  const int blas_threads = openblas_get_num_threads();
  if (per_prompt) openblas_set_num_threads(1);
  auto body = [&](long b0, long b1) {
    // oneDNN's products (bf16) run on OpenMP threads of the calling thread: one each when prompts are split.
    const int omp_threads = omp_get_max_threads();
    if (per_prompt) omp_set_num_threads(1);
    thread_local Work work;  // kept from batch to batch (fresh buffers cost page faults and zeroing)
    for (long b = b0; b < b1; ++b) decode_prompt(d, s, sparse + size_t(b) * T * s.C, T, work, res[b]);
    if (per_prompt) omp_set_num_threads(omp_threads);
  };
  if (per_prompt) nn::parallel_for(B, 2, body);
  else body(0, B);
  if (per_prompt) openblas_set_num_threads(blas_threads);
  return res;
}

Prediction SamModel::predict(const ImageEmbedding& e, const Prompt& p) const {
  if (e.grid != vision.grid || e.channels != channels())
    fail("SAM: image embedding of grid {} x {} channels does not match the model ({} x {})", e.grid, e.channels,
         vision.grid, channels());
  const std::vector<float> sparse = encode_prompt(to_input(e, p));
  const int T = int(sparse.size()) / channels();
  return decode(e.data.data(), sparse.data(), 1, T).front();
}

}  // namespace hgs::sam
