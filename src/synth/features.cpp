// Simulated CLIP: every phrase has a fixed unit "concept" vector in R^D seeded by its text. A view's dense
// feature map lives on a 16-pixel patch grid; each patch is the area-weighted mean of the concepts of the
// surfaces visible in it, blended with its 8 neighbours (CLIP's receptive field), plus a scene-wide context
// vector and Gaussian noise, then L2-normalised. Upsampled to pixels, object boundaries bleed like real
// MaskCLIP features.
#include <cmath>

#include "synth/synth.h"

namespace hgs::synth {

std::vector<float> concept_vector(const std::string& phrase, int dim) {
  Rng rng(hash_string("concept:" + phrase));
  std::vector<float> v(dim);
  double s = 0;
  for (auto& x : v) {
    x = static_cast<float>(rng.normal());
    s += double(x) * x;
  }
  float inv = static_cast<float>(1.0 / std::sqrt(s));
  for (auto& x : v) x *= inv;
  return v;
}

std::vector<float> simulate_features(const RenderedView& v, const std::vector<std::vector<float>>& concepts,
                                     const std::vector<float>& context, double noise, int dim, uint64_t seed, int& gh,
                                     int& gw) {
  const int P = 16, W = v.rgb.width, H = v.rgb.height;
  gh = (H + P - 1) / P;
  gw = (W + P - 1) / P;
  const size_t nc = concepts.size();
  std::vector<double> hist(size_t(gh) * gw * nc, 0.0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) hist[(size_t(y / P) * gw + x / P) * nc + v.concept_id[size_t(y) * W + x]] += 1;
  std::vector<float> raw(size_t(gh) * gw * dim, 0.f);
  for (int py = 0; py < gh; ++py)
    for (int px = 0; px < gw; ++px) {
      const double* hp = &hist[(size_t(py) * gw + px) * nc];
      double total = 0;
      for (size_t c = 0; c < nc; ++c) total += hp[c];
      float* o = &raw[(size_t(py) * gw + px) * dim];
      for (size_t c = 0; c < nc; ++c) {
        if (hp[c] == 0) continue;
        float a = static_cast<float>(hp[c] / total);
        for (int d = 0; d < dim; ++d) o[d] += a * concepts[c][d];
      }
    }
  Rng rng(seed);
  const float nscale = static_cast<float>(noise / std::sqrt(double(dim)));
  std::vector<float> out(raw.size());
  for (int py = 0; py < gh; ++py)
    for (int px = 0; px < gw; ++px) {
      float* o = &out[(size_t(py) * gw + px) * dim];
      float wsum = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          int qy = py + dy, qx = px + dx;
          if (qy < 0 || qy >= gh || qx < 0 || qx >= gw) continue;
          float wgt = (dx == 0 && dy == 0) ? 0.6f : 0.05f;
          const float* r = &raw[(size_t(qy) * gw + qx) * dim];
          for (int d = 0; d < dim; ++d) o[d] += wgt * r[d];
          wsum += wgt;
        }
      double s = 0;
      for (int d = 0; d < dim; ++d) {
        o[d] = o[d] / wsum + 0.35f * context[d] + nscale * static_cast<float>(rng.normal());
        s += double(o[d]) * o[d];
      }
      float inv = static_cast<float>(1.0 / std::sqrt(std::max(s, 1e-20)));
      for (int d = 0; d < dim; ++d) o[d] *= inv;
    }
  return out;
}

}  // namespace hgs::synth
