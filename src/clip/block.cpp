// CLIP's transformer block: see block.h.
#include "clip/block.h"

#include <cmath>

#include "nn/transformer.h"

namespace hgs::clip {

void Workspace::reserve(int n, int width, int mlp_width, int max_len) {
  h.resize(size_t(n) * width);
  qkv.resize(size_t(n) * 3 * width);
  attn.resize(size_t(n) * width);
  mlp.resize(size_t(n) * mlp_width);
  scores.resize(size_t(max_len) * max_len);
}

void block_forward(const Block& b, int heads, Activation act, const std::vector<Segment>& segs, bool causal, float* x,
                   int n, Workspace& ws) {
  const int w = b.qkv.in, hd = w / heads, w3 = 3 * w;
  const float scale = 1.f / std::sqrt(float(hd));
  // Attention.
  nn::layer_norm(b.ln1, x, n, w, ws.h.data());
  nn::linear(b.qkv, ws.h.data(), n, ws.qkv.data());
  for (const Segment& sg : segs) {
    const float* base = ws.qkv.data() + size_t(sg.start) * w3;
    nn::multi_head_attention(base, w3, base + w, w3, base + 2 * w, w3, sg.len, sg.len, heads, hd, scale,
                             ws.attn.data() + size_t(sg.start) * w, w, ws.scores.data(), causal);
  }
  nn::linear_add(b.out, ws.attn.data(), n, x);
  // MLP.
  nn::layer_norm(b.ln2, x, n, w, ws.h.data());
  nn::linear(b.fc, ws.h.data(), n, ws.mlp.data());
  nn::activation(act, ws.mlp.data(), size_t(n) * b.fc.out);
  nn::linear_add(b.proj, ws.mlp.data(), n, x);
}

}  // namespace hgs::clip
