// SAM's prompt encoder. Positions are encoded with random Fourier features: a point (x, y) normalised to
// [0, 1] by the input size becomes u = 2 pi (2 (x, y) - 1) G for the fixed Gaussian matrix G [2, C / 2], and the
// encoding is [sin u, cos u]. Points add their label's learned embedding (label -1 / the padding point gets
// the "not a point" embedding instead of a position); box corners add corner embeddings. Pixel centres are
// at +0.5. The dense positional encoding of the embedding grid uses cell centres ((j + 0.5) / g, (i + 0.5) / g).
#include <cmath>

#include "core/error.h"
#include "nn/thread_pool.h"
#include "sam/model.h"

namespace hgs::sam {
namespace {

// out [C] = [sin u, cos u], u = 2 pi ((2 x - 1) G[0] + (2 y - 1) G[1]); x, y in [0, 1]. G [2, C / 2].
void fourier(const std::vector<float>& G, int C, float x, float y, float* out) {
  const int h = C / 2;
  const float cx = 2.f * x - 1.f, cy = 2.f * y - 1.f;
  for (int i = 0; i < h; ++i) {
    const float u = 2.f * float(M_PI) * (cx * G[i] + cy * G[h + i]);
    out[i] = std::sin(u);
    out[h + i] = std::cos(u);
  }
}

}  // namespace

std::vector<float> SamModel::dense_pe() const {
  const int g = vision.grid, C = channels();
  std::vector<float> pe(size_t(g) * g * C);
  nn::parallel_for(g, 2, [&](long i0, long i1) {  // 1 M sines and cosines at ViT-B: rows on the pool
    for (long i = i0; i < i1; ++i)
      for (int j = 0; j < g; ++j)
        fourier(prompt.gauss, C, (j + 0.5f) / g, (i + 0.5f) / g, pe.data() + (size_t(i) * g + j) * C);
  });
  return pe;
}

std::vector<float> SamModel::encode_prompt(const Prompt& p) const {
  const int C = channels();
  const float S = float(image_size());
  if (p.points.size() != p.labels.size()) fail("SAM prompt: {} points but {} labels", p.points.size(), p.labels.size());
  if (p.points.empty() && p.boxes.empty()) fail("SAM prompt: no point and no box");
  const bool pad = p.boxes.empty();
  const size_t T = p.points.size() + (pad ? 1 : 0) + 2 * p.boxes.size();
  std::vector<float> out(T * C);
  size_t t = 0;
  for (size_t i = 0; i < p.points.size(); ++i, ++t) {
    float* o = out.data() + t * C;
    const int lab = p.labels[i];
    if (lab < -1 || lab > 1) fail("SAM prompt: point label {} (1 foreground, 0 background, -1 ignored)", lab);
    if (lab == -1) {
      std::copy(prompt.not_a_point.begin(), prompt.not_a_point.end(), o);
      continue;
    }
    fourier(prompt.gauss, C, (p.points[i][0] + 0.5f) / S, (p.points[i][1] + 0.5f) / S, o);
    const auto& e = prompt.point[lab];
    for (int c = 0; c < C; ++c) o[c] += e[c];
  }
  if (pad) std::copy(prompt.not_a_point.begin(), prompt.not_a_point.end(), out.data() + (t++) * C);
  for (const auto& b : p.boxes)
    for (int k = 0; k < 2; ++k, ++t) {
      float* o = out.data() + t * C;
      fourier(prompt.gauss, C, (b[2 * k] + 0.5f) / S, (b[2 * k + 1] + 0.5f) / S, o);
      const auto& e = prompt.point[2 + k];
      for (int c = 0; c < C; ++c) o[c] += e[c];
    }
  return out;
}

Prompt SamModel::to_input(const ImageEmbedding& e, const Prompt& p) const {
  const float sx = float(e.input_w) / float(e.orig_w), sy = float(e.input_h) / float(e.orig_h);
  Prompt q = p;
  for (auto& pt : q.points) pt = {pt[0] * sx, pt[1] * sy};
  for (auto& b : q.boxes) b = {b[0] * sx, b[1] * sy, b[2] * sx, b[3] * sy};
  return q;
}

}  // namespace hgs::sam
