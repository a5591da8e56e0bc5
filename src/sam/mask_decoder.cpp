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

}  // namespace

std::vector<Prediction> SamModel::decode(const float* emb, const float* sparse, int B, int T) const {
  const MaskDecoder& d = decoder;
  const int C = channels(), g = vision.grid, N = g * g, heads = d.heads;
  const int Tt = 1 + d.tokens + T;  // iou token, mask tokens, prompt tokens
  if (d.layers.empty()) fail("SAM mask decoder has no layers");
  const std::vector<float> pe = dense_pe();  // [N, C]
  std::vector<float> src0(size_t(N) * C), kpe(size_t(N) * C);
  nn::parallel_for(N, 64, [&](long t0, long t1) {  // image tokens on the pool (serial, they capped the scaling)
    for (size_t i = size_t(t0) * C; i < size_t(t1) * C; ++i) {
      src0[i] = emb[i] + prompt.no_mask[i % C];
      kpe[i] = src0[i] + pe[i];
    }
  });
  // The first block's token-to-image keys / values: the same for every prompt.
  Proj kv0;
  const Attention& a0 = d.layers[0].token_to_image;
  kv0.k.resize(size_t(N) * a0.k.out);
  kv0.v.resize(size_t(N) * a0.v.out);
  nn::linear(a0.k, kpe.data(), N, kv0.k.data());
  nn::linear(a0.v, src0.data(), N, kv0.v.data());
  // ... and the first block's image-to-token query projection.
  const Attention& i0 = d.layers[0].image_to_token;
  std::vector<float> q0(size_t(N) * i0.q.out);
  nn::linear(i0.q, kpe.data(), N, q0.data());

  // bf16: the first block's keys and values split by head and rounded once per batch (multi_head_attention_bf16).
  const bool bf16 = precision == nn::Precision::BF16;
  const int I0 = a0.q.out, hd0 = I0 / heads;
  std::vector<uint16_t> k0_16, v0_16;
  if (bf16) {
    k0_16.resize(size_t(N) * I0);
    v0_16.resize(size_t(N) * I0);
    nn::split_heads_bf16(kv0.k.data(), N, I0, heads, hd0, k0_16.data());
    nn::split_heads_bf16(kv0.v.data(), N, I0, heads, hd0, v0_16.data());
  }

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
    // Work buffers of this thread, kept from batch to batch (fresh ones cost page faults and zeroing).
    thread_local Work work;
    Proj& w = work.w;
    AttnWork& aw = work.aw;
    std::vector<float>&scores = work.scores, &q = work.q, &qpe = work.qpe, &keys = work.keys, &tmp = work.tmp,
    &qq = work.qq, &kk = work.kk, &mlp = work.mlp, &y = work.y, &u1 = work.u1, &u2 = work.u2;
    std::vector<uint16_t>&x16 = work.x16, &kk16 = work.kk16, &keys16 = work.keys16;
    std::vector<float>& qproj = work.qproj;
    // kk (f32) or kk16 and keys16 (bf16) from the current keys.
    auto image_operands = [&] {
      if (bf16) {
        kk16.resize(keys.size());
        keys16.resize(keys.size());
        nn::sum_to_bf16_serial(keys.data(), pe.data(), keys.size(), kk16.data());
        nn::convert_to_bf16_serial(keys.data(), N, C, C, keys16.data());
      } else {
        add(keys.data(), pe.data(), keys.size(), kk);
      }
    };
    q.resize(size_t(Tt) * C);
    for (long b = b0; b < b1; ++b) {
      std::copy(d.iou_token.begin(), d.iou_token.end(), q.begin());
      std::copy(d.mask_tokens.begin(), d.mask_tokens.end(), q.begin() + C);
      std::copy_n(sparse + size_t(b) * T * C, size_t(T) * C, q.begin() + size_t(1 + d.tokens) * C);
      qpe = q;
      keys = src0;
      tmp.resize(std::max(size_t(Tt), size_t(N)) * C);
      for (size_t li = 0; li < d.layers.size(); ++li) {
        const TwoWayLayer& l = d.layers[li];
        if (li == 0) {
          attend(l.self_attn, heads, q.data(), Tt, q.data(), q.data(), Tt, tmp.data(), w, scores);
          std::copy_n(tmp.data(), size_t(Tt) * C, q.data());
        } else {
          add(q.data(), qpe.data(), q.size(), qq);
          attend(l.self_attn, heads, qq.data(), Tt, qq.data(), q.data(), Tt, tmp.data(), w, scores);
          for (size_t i = 0; i < q.size(); ++i) q[i] += tmp[i];
        }
        nn::layer_norm(l.ln1, q.data(), Tt, C, q.data(), d.ln_eps);
        add(q.data(), qpe.data(), q.size(), qq);
        if (li == 0 && bf16) {
          const Attention& a = l.token_to_image;
          w.q.resize(size_t(Tt) * I0);
          w.o.resize(size_t(Tt) * I0);
          scores.resize(size_t(Tt) * N);
          nn::linear(a.q, qq.data(), Tt, w.q.data());
          nn::multi_head_attention_bf16(w.q.data(), I0, k0_16.data(), v0_16.data(), Tt, N, heads, hd0,
                                        1.f / std::sqrt(float(hd0)), w.o.data(), I0, scores.data());
          nn::linear(a.out, w.o.data(), Tt, tmp.data());
        } else if (li == 0) {
          attend(l.token_to_image, heads, qq.data(), Tt, nullptr, nullptr, N, tmp.data(), w, scores, &kv0);
        } else {
          image_operands();
          attend_few_queries(l.token_to_image, heads, qq.data(), Tt, kk.data(), keys.data(), N, tmp.data(), aw, bf16,
                             kk16.data(), keys16.data());
        }
        for (size_t i = 0; i < q.size(); ++i) q[i] += tmp[i];
        nn::layer_norm(l.ln2, q.data(), Tt, C, q.data(), d.ln_eps);
        mlp.resize(size_t(Tt) * l.mlp1.out);
        nn::linear(l.mlp1, q.data(), Tt, mlp.data());
        relu(mlp.data(), mlp.size());
        nn::linear_add(l.mlp2, mlp.data(), Tt, q.data());
        nn::layer_norm(l.ln3, q.data(), Tt, C, q.data(), d.ln_eps);
        add(q.data(), qpe.data(), q.size(), qq);
        // kk = keys + pe is still current for li > 0 (the token-to-image attention changed the tokens only).
        const float* qp = li == 0 ? q0.data() : nullptr;
        if (li > 0 && bf16) {  // the query projection from the rounded kk16 of the token-to-image attention
          const Linear& lq = l.image_to_token.q;
          qproj.resize(size_t(N) * lq.out);
          nn::gemm_bf16(N, lq.out, C, kk16.data(), C, lq.w16.data(), C, true, 1.f, lq.b.data(), 0.f, qproj.data(),
                        lq.out);
          qp = qproj.data();
        }
        attend_few_keys(l.image_to_token, heads, qp ? nullptr : kk.data(), qp, N, qq.data(), q.data(), Tt, tmp.data(),
                        aw, bf16);
        for (size_t i = 0; i < keys.size(); ++i) keys[i] += tmp[i];
        nn::layer_norm(l.ln4, keys.data(), N, C, keys.data(), d.ln_eps);
      }
      add(q.data(), qpe.data(), q.size(), qq);
      image_operands();
      attend_few_queries(d.final_attn, heads, qq.data(), Tt, kk.data(), keys.data(), N, tmp.data(), aw, bf16,
                         kk16.data(), keys16.data());
      for (size_t i = 0; i < q.size(); ++i) q[i] += tmp[i];
      nn::layer_norm(d.ln_final, q.data(), Tt, C, q.data(), d.ln_final_eps);

      // Upscaling: [g, g, C] -> [2g, 2g, C/4] (LN, GELU) -> [4g, 4g, C/8] (GELU).
      upconv(d.up1, keys.data(), g, y, x16, u1, bf16 ? keys16.data() : nullptr);  // keys16 is still current
      nn::layer_norm(d.up_ln, u1.data(), 4 * N, d.up1.out, u1.data(), 1e-6f);
      nn::activation(nn::Activation::GELU, u1.data(), u1.size());
      upconv(d.up2, u1.data(), 2 * g, y, x16, u2);
      const int D = d.up2.out, P = 16 * N;
      std::vector<float> hyper(size_t(d.tokens) * D);
      for (int t = 0; t < d.tokens; ++t) {
        std::vector<float> h = run_mlp(d.hyper[t], q.data() + size_t(1 + t) * C);
        if (int(h.size()) != D)
          fail("SAM hypernetwork {} gives {} values, the upscaled embedding has {}", t, h.size(), D);
        std::copy(h.begin(), h.end(), hyper.begin() + size_t(t) * D);
      }
      Prediction& r = res[b];
      r.tokens = d.tokens;
      r.size = 4 * g;
      r.lowres.resize(size_t(d.tokens) * P);
      // masks [tokens, P] = hyper [tokens, D] x GELU(u2)^T [D, P], the GELU and the dot products of a block of
      // pixels in one pass while the block is in cache (a separate GELU pass and sgemm read u2 twice).
      constexpr int kBlock = 128;
      for (int p0 = 0; p0 < P; p0 += kBlock) {
        const int np = std::min(kBlock, P - p0);
        float* px = u2.data() + size_t(p0) * D;
        nn::gelu_serial(px, long(np) * D);
        for (int t = 0; t < d.tokens; ++t) {
          const float* h = hyper.data() + size_t(t) * D;
          float* o = r.lowres.data() + size_t(t) * P + p0;
          for (int i = 0; i < np; ++i) {
            const float* x = px + size_t(i) * D;
            float acc = 0.f;
#pragma omp simd reduction(+ : acc)
            for (int c = 0; c < D; ++c) acc += h[c] * x[c];
            o[i] = acc;
          }
        }
      }
      r.iou = run_mlp(d.iou_head, q.data());
    }
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
