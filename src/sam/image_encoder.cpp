// SAM's ViT image encoder and neck on HWC token matrices.
//   patch embedding: im2col of the P x P patches (c, ky, kx) times the conv weight, plus the absolute positions;
//   layer: x += proj(attn(LN1(x))); x += lin2(GELU(lin1(LN2(x)))), LayerNorm eps 1e-6; the attention and MLP
//     widths and the head count are the layer's own (SlimSAM's pruned models), the residual width is shared. Windowed
//     layers cut the normalised tokens into w x w windows after zero-padding the grid to a multiple of w (padded tokens
//     take part as keys with value bias, as in SAM) and attend within each; global layers attend over the whole grid.
//     Attention adds the decomposed relative positions before the softmax: for query (i, j) and key (k, l),
//     q . Rh[i - k + s - 1] + q . Rw[j - l + s - 1] with the unscaled query (s = window or grid side); the two
//     tables of dot products come from one sgemm each (q [n, hd] x R^T [hd, 2s - 1]) and are gathered. Global
//     attention runs in blocks of query rows so that the scores stay in cache.
//   neck: 1x1 conv, channel LayerNorm, 3x3 conv (pad 1, im2col), channel LayerNorm (eps 1e-6, no biases).
#include <cblas.h>
#include <omp.h>
#include <algorithm>
#include <cmath>
#include <functional>

#include "core/error.h"
#include "nn/thread_pool.h"
#include "nn/transformer.h"
#include "sam/model.h"

namespace hgs::sam {
namespace {

constexpr float kVitEps = 1e-6f;

// Relative-position bias of one head for the query rows [row0, row0 + nq) of an s x s grid (n = s * s keys):
// adds to scores [nq, n] the terms q . rel_h[q_row - k_row + s - 1] + q . rel_w[q_col - k_col + s - 1];
// q [nq, hd] (those rows) with row stride ldq.
void add_rel_pos(const float* q, int ldq, int row0, int nq, int s, int hd, const float* rel_h, const float* rel_w,
                 float* scores, std::vector<float>& th, std::vector<float>& tw) {
  const int n = s * s, r = 2 * s - 1;
  th.resize(size_t(nq) * r);
  tw.resize(size_t(nq) * r);
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, nq, r, hd, 1.f, q, ldq, rel_h, hd, 0.f, th.data(), r);
  cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, nq, r, hd, 1.f, q, ldq, rel_w, hd, 0.f, tw.data(), r);
  nn::parallel_for(nq, 16, [&](long i0, long i1) {
    for (long i = i0; i < i1; ++i) {
      const int qi = int(row0 + i) / s, qj = int(row0 + i) % s;
      const float* a = th.data() + size_t(i) * r;
      const float* b = tw.data() + size_t(i) * r;
      float* row = scores + size_t(i) * n;
      for (int k = 0; k < s; ++k) {
        const float hk = a[qi - k + s - 1];
        float* rk = row + size_t(k) * s;
        for (int l = 0; l < s; ++l) rk[l] += hk + b[qj - l + s - 1];
      }
    }
  });
}

struct VitWork {
  std::vector<float> h, win, qkv, attn, out, mlp;
  std::vector<uint16_t> k16, v16;  // [windows, heads, n, hd] keys and values in bf16 (Precision::BF16)
};

// Attention of one layer on the normalised tokens h [g * g, C]; adds proj(attn) to x [g * g, C]. The layer's
// own attention width I = qkv.out / 3 = heads * hd (pruned models differ per layer) sets the widths of q, k, v
// and of the attention output (proj: I -> C).
void vit_attention(const VitLayer& l, int g, int C, int heads, bool bf16, const float* h, float* x, VitWork& w) {
  const int I = l.qkv.out / 3, hd = I / heads;
  const float scale = 1.f / std::sqrt(float(hd));
  const int s = l.window > 0 ? l.window : g;          // side of one attention grid
  const int nw = l.window > 0 ? (g + s - 1) / s : 1;  // windows per side
  const int n = s * s, M = nw * nw * n;               // tokens per window, all (padded) tokens
  // Gather windows: token (wy, wx, i, j) <- grid (wy * s + i, wx * s + j), zero outside the grid; rows of
  // windows in parallel (every copy and scatter of this file runs on the pool: a serial pass over the 3 M
  // values of the token grid is a few percent of a layer at one thread, and so caps the scaling).
  w.win.resize(size_t(M) * C);
  nn::parallel_for(long(nw) * s, 2, [&](long r0, long r1) {
    for (long r = r0; r < r1; ++r) {
      const int wy = int(r / s), i = int(r % s), y = wy * s + i;
      for (int wx = 0; wx < nw; ++wx)
        for (int j = 0; j < s; ++j) {
          const int xx = wx * s + j;
          float* d = w.win.data() + ((size_t(wy * nw + wx) * n) + i * s + j) * C;
          if (y >= g || xx >= g) std::fill_n(d, C, 0.f);
          else std::copy_n(h + (size_t(y) * g + xx) * C, C, d);
        }
    }
  });
  w.qkv.resize(size_t(M) * 3 * I);
  nn::linear(l.qkv, w.win.data(), M, w.qkv.data());
  w.attn.resize(size_t(M) * I);
  if (bf16) {  // keys and values rounded once for every query block, each window's heads contiguous
    w.k16.resize(size_t(M) * I);
    w.v16.resize(size_t(M) * I);
    if (nw == 1) {  // one global window: split_heads_bf16 runs its rows on the pool
      nn::split_heads_bf16(w.qkv.data() + I, n, 3 * I, heads, hd, w.k16.data());
      nn::split_heads_bf16(w.qkv.data() + 2 * I, n, 3 * I, heads, hd, w.v16.data());
    } else {
      nn::parallel_for(nw * nw, 2, [&](long w0, long w1) {
        for (long wi = w0; wi < w1; ++wi) {
          const float* base = w.qkv.data() + size_t(wi) * n * 3 * I;
          nn::split_heads_bf16(base + I, n, 3 * I, heads, hd, w.k16.data() + size_t(wi) * n * I);
          nn::split_heads_bf16(base + 2 * I, n, 3 * I, heads, hd, w.v16.data() + size_t(wi) * n * I);
        }
      });
    }
  }
  // Query blocks keep the score matrix [rows, n] within ~2 MB (cache) for the global layers. The (window,
  // block) units are independent: one per thread with single-threaded OpenBLAS (one hand-off per layer instead
  // of several per head).
  // The units are equal in cost, so with T threads they are cut until T divides their count or there are at
  // least 8 per thread (windowed layers: 25 windows at ViT-B, 13 + 12 on two threads lost ~4 % of the attention).
  const int T = nn::pool_threads();
  int rows = std::min(n, std::max(16, (1 << 19) / n));
  int blocks = (n + rows - 1) / rows;
  for (int b = blocks + 1; T > 1 && (nw * nw * blocks) % T != 0 && nw * nw * blocks < 8 * T && (n + b - 1) / b >= 16;
       ++b)
    rows = (n + b - 1) / b, blocks = (n + rows - 1) / rows;
  const int units = nw * nw * blocks;
  const bool split = units > 1 && T > 1;
  const int blas_threads = openblas_get_num_threads();
  if (split) openblas_set_num_threads(1);
  auto run = [&](long u0, long u1) {
    // oneDNN's products (bf16) run on OpenMP threads of the calling thread: one each when units are split.
    const int omp_threads = omp_get_max_threads();
    if (split) omp_set_num_threads(1);
    std::vector<float> scores(size_t(rows) * n), th, tw;
    for (long u = u0; u < u1; ++u) {
      const int wi = int(u / blocks), r0 = int(u % blocks) * rows, nq = std::min(rows, n - r0);
      const float* base = w.qkv.data() + size_t(wi) * n * 3 * I;
      const float* qb = base + size_t(r0) * 3 * I;
      std::function<void(int, float*)> bias;
      if (!l.rel_h.empty())
        bias = [&](int head, float* sc) {
          add_rel_pos(qb + head * hd, 3 * I, r0, nq, s, hd, l.rel_h.data(), l.rel_w.data(), sc, th, tw);
        };
      float* out = w.attn.data() + (size_t(wi) * n + r0) * I;
      if (bf16) {
        nn::multi_head_attention_bf16(qb, 3 * I, w.k16.data() + size_t(wi) * n * I, w.v16.data() + size_t(wi) * n * I,
                                      nq, n, heads, hd, scale, out, I, scores.data(), false, bias);
      } else {
        nn::multi_head_attention(qb, 3 * I, base + I, 3 * I, base + 2 * I, 3 * I, nq, n, heads, hd, scale, out, I,
                                 scores.data(), false, bias);
      }
    }
    if (split) omp_set_num_threads(omp_threads);
  };
  if (split) nn::parallel_for(units, 2, run);
  else run(0, units);
  if (split) openblas_set_num_threads(blas_threads);
  w.out.resize(size_t(M) * C);
  nn::linear(l.proj, w.attn.data(), M, w.out.data());
  // Scatter back, grid rows in parallel (each grid token is in exactly one window).
  nn::parallel_for(g, 2, [&](long y0, long y1) {
    for (long y = y0; y < y1; ++y) {
      const int wy = int(y) / s, i = int(y) % s;
      for (int xx = 0; xx < g; ++xx) {
        const int wx = xx / s, j = xx % s;
        const float* o = w.out.data() + ((size_t(wy * nw + wx) * n) + i * s + j) * C;
        float* d = x + (size_t(y) * g + xx) * C;
        for (int c = 0; c < C; ++c) d[c] += o[c];
      }
    }
  });
}

// im2col of a 3x3 convolution with zero padding 1 on x [g, g, C]: cols [g * g, 9 * C] ordered (ky, kx, c).
void im2col3x3(const float* x, int g, int C, std::vector<float>& cols) {
  cols.resize(size_t(g) * g * 9 * C);
  nn::parallel_for(g, 2, [&](long y0, long y1) {
    for (long y = y0; y < y1; ++y)
      for (int xx = 0; xx < g; ++xx) {
        float* o = cols.data() + (size_t(y) * g + xx) * 9 * C;
        for (int ky = 0; ky < 3; ++ky)
          for (int kx = 0; kx < 3; ++kx) {
            const int sy = int(y) + ky - 1, sx = xx + kx - 1;
            float* d = o + (ky * 3 + kx) * C;
            if (sy < 0 || sy >= g || sx < 0 || sx >= g) std::fill_n(d, C, 0.f);
            else std::copy_n(x + (size_t(sy) * g + sx) * C, C, d);
          }
      }
  });
}

}  // namespace

std::vector<float> SamModel::encode(const float* x, std::vector<std::vector<float>>* stages) const {
  const VisionEncoder& v = vision;
  const int g = v.grid, P = v.patch, C = v.hidden, N = g * g, S = image_size(), K = 3 * P * P;
  // Patch embedding: cols [N, 3 * P * P] ordered (c, ky, kx) like the conv weight.
  std::vector<float> cols(size_t(N) * K);
  nn::parallel_for(g, 2, [&](long p0, long p1) {
    for (long py = p0; py < p1; ++py)
      for (int px = 0; px < g; ++px) {
        float* o = cols.data() + (size_t(py) * g + px) * K;
        for (int c = 0; c < 3; ++c)
          for (int ky = 0; ky < P; ++ky)
            for (int kx = 0; kx < P; ++kx)
              o[(c * P + ky) * P + kx] = x[((size_t(py) * P + ky) * S + px * P + kx) * 3 + c];
      }
  });
  std::vector<float> tok(size_t(N) * C);
  nn::linear(v.patch_embed, cols.data(), N, tok.data());
  nn::parallel_for(N, 64, [&](long t0, long t1) {
    for (size_t i = size_t(t0) * C; i < size_t(t1) * C; ++i) tok[i] += v.pos[i];
  });
  if (stages) {
    stages->clear();
    stages->push_back(tok);
  }
  VitWork w;
  w.h.resize(size_t(N) * C);
  for (const VitLayer& l : v.layers) {
    nn::layer_norm(l.ln1, tok.data(), N, C, w.h.data(), kVitEps);
    vit_attention(l, g, C, l.heads > 0 ? l.heads : v.heads, precision == nn::Precision::BF16, w.h.data(), tok.data(),
                  w);
    nn::layer_norm(l.ln2, tok.data(), N, C, w.h.data(), kVitEps);
    w.mlp.resize(size_t(N) * l.fc1.out);
    nn::linear(l.fc1, w.h.data(), N, w.mlp.data());
    nn::activation(nn::Activation::GELU, w.mlp.data(), w.mlp.size());
    nn::linear_add(l.fc2, w.mlp.data(), N, tok.data());
    if (stages) stages->push_back(tok);
  }
  // Neck.
  const int O = v.out;
  std::vector<float> a(size_t(N) * O), out(size_t(N) * O);
  nn::linear(v.neck1, tok.data(), N, a.data());
  nn::layer_norm(v.neck_ln1, a.data(), N, O, a.data(), kVitEps);
  im2col3x3(a.data(), g, O, cols);
  nn::linear(v.neck2, cols.data(), N, out.data());
  nn::layer_norm(v.neck_ln2, out.data(), N, O, out.data(), kVitEps);
  return out;
}

ImageEmbedding SamModel::embed(const Image& img) const {
  ImageEmbedding e;
  std::vector<float> x = preprocess(img, &e.input_h, &e.input_w);
  e.data = encode(x.data());
  e.grid = vision.grid;
  e.channels = vision.out;
  e.orig_h = img.height;
  e.orig_w = img.width;
  return e;
}

}  // namespace hgs::sam
