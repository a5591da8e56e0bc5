// CLIP text encoder. Each phrase [sot, ..., eot] is embedded (token + positional embedding) and all phrases
// are packed into one token matrix; the causal mask means the pooled token (the first eot, i.e. the argmax of
// the ids as in CLIP) depends only on the tokens before it, so each phrase is cut right after that token and
// the padding CLIP runs through the model is skipped (same result, less work). Output: ln_final(x[eot]) @ proj.
#include <algorithm>

#include "clip/block.h"
#include "clip/model.h"
#include "clip/tokenizer.h"
#include "core/error.h"
#include "nn/transformer.h"

namespace hgs::clip {

std::vector<float> ClipModel::embed_tokens(const std::vector<std::vector<int>>& ids, bool normalize) const {
  if (!has_text) fail("{}: the model has no text tower", path.string());
  const int w = text.tr.width, D = embed_dim;
  std::vector<Segment> segs;
  int n = 0, max_len = 1;
  for (auto& seq : ids) {
    if (seq.empty()) fail("embed_tokens: empty token sequence");
    // Pool at the first maximal id (CLIP's argmax); later tokens cannot influence it.
    int pool = int(std::max_element(seq.begin(), seq.end()) - seq.begin());
    int len = std::min(pool + 1, text.context);
    segs.push_back({n, len});
    n += len;
    max_len = std::max(max_len, len);
  }
  std::vector<float> x(size_t(n) * w);
  for (size_t s = 0; s < ids.size(); ++s)
    for (int i = 0; i < segs[s].len; ++i) {
      int id = ids[s][i];
      if (id < 0 || id >= text.vocab)
        fail("{}: token id {} outside the vocabulary of {}", path.string(), id, text.vocab);
      float* r = x.data() + size_t(segs[s].start + i) * w;
      const float* e = text.tok_emb.data() + size_t(id) * w;
      const float* p = text.pos.data() + size_t(i) * w;
      for (int j = 0; j < w; ++j) r[j] = e[j] + p[j];
    }
  Workspace ws;
  ws.reserve(n, w, text.tr.blocks.empty() ? w : text.tr.blocks[0].fc.out, max_len);
  for (const Block& b : text.tr.blocks) block_forward(b, text.tr.heads, act, segs, /*causal=*/true, x.data(), n, ws);
  // Pooled rows -> ln_final -> projection.
  const int T = int(ids.size());
  std::vector<float> pooled(size_t(T) * w), out(size_t(T) * D);
  for (int s = 0; s < T; ++s) {
    const float* r = x.data() + size_t(segs[s].start + segs[s].len - 1) * w;
    std::copy(r, r + w, pooled.data() + size_t(s) * w);
  }
  nn::layer_norm(text.ln_final, pooled.data(), T, w, pooled.data());
  nn::matmul(pooled.data(), T, w, text.proj.data(), D, out.data());
  if (normalize) nn::l2_normalize_rows(out.data(), T, D);
  return out;
}

std::vector<float> ClipModel::embed_text(const std::vector<std::string>& phrases) const {
  if (!has_text) fail("{}: the model has no text tower", path.string());
  const Tokenizer& tok = Tokenizer::shared();
  std::vector<std::vector<int>> ids;
  for (auto& p : phrases) ids.push_back(tok.tokenize(p, text.context));
  return embed_tokens(ids, true);
}

}  // namespace hgs::clip
