// CLIP's pre-LayerNorm transformer block (x += attn(ln_1(x)); x += mlp(ln_2(x))) on the kernels of
// nn/transformer.h. Several independent sequences can be packed into one token matrix (`Segment`s): linear layers
// see all of them at once, attention stays within each. Buffers live in a Workspace sized once per forward call;
// nothing is allocated per token or per layer.
#pragma once
#include <vector>

#include "clip/model.h"

namespace hgs::clip {

struct Segment {
  int start = 0, len = 0;  // rows [start, start + len) of the token matrix
};

struct Workspace {
  std::vector<float> h;       // [N, width]
  std::vector<float> qkv;     // [N, 3 * width]
  std::vector<float> attn;    // [N, width]
  std::vector<float> mlp;     // [N, mlp]
  std::vector<float> scores;  // [max_len, max_len]
  void reserve(int n, int width, int mlp_width, int max_len);
};

// One block applied in place to x [N, width].
void block_forward(const Block& b, int heads, Activation act, const std::vector<Segment>& segs, bool causal, float* x,
                   int n, Workspace& ws);

}  // namespace hgs::clip
