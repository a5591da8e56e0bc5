// The realistic world's dense language features, as MaskCLIP gives them from a ViT-B/16 (one feature per patch
// of the grid `hgs features --input-size 448` gives, upsampled by the user): a patch's content is the area-weighted
// mean of the contents (language.h) of the things visible in it, each with a per-view bias (an object looks different
// from each side); blurred with its 8 neighbours (the patch tokens' receptive field: centre 0.4, sides 0.1, corners
// 0.05), 15 % of it replaced by the view's mean content (the global token leaking into every patch), plus per-patch
// confusion (a random mixture of the scene's contents: MaskCLIP's noisy per-patch class) and isotropic noise; finally
// in the image cone:
//   f = normalise(kImageShared g_I + kContent (content + confusion) + noise).
// Boundaries, small objects and thin parts blur into their surroundings, as real dense CLIP features do.
#include <algorithm>
#include <cmath>

#include "synth/language.h"
#include "synth/synth.h"

namespace hgs::synth {

std::vector<float> simulate_dense_features(const RenderedView& v, const std::vector<std::vector<float>>& contents,
                                           const NoiseLevel& nl, int dim, uint64_t seed, int& gh, int& gw) {
  // The grid `hgs features` gives a real capture (shorter side resized to 448 px = 28 patches of 16): 28 cells on
  // the shorter side whatever the image size, so an object covers as many patches as in a real capture.
  const int W = v.rgb.width, H = v.rgb.height;
  if (H <= W) {
    gh = std::min(kGridShort, H);
    gw = std::min(W, std::max(1, int(std::lround(double(W) * gh / H))));
  } else {
    gw = std::min(kGridShort, W);
    gh = std::min(H, std::max(1, int(std::lround(double(H) * gw / W))));
  }
  const size_t nc = contents.size(), np = size_t(gh) * gw;
  Rng rng(seed);
  // The concepts with content: the basis of the view bias and the confusion.
  std::vector<size_t> basis;
  for (size_t c = 0; c < nc; ++c) {
    double s = 0;
    for (float x : contents[c]) s += double(x) * x;
    if (s > 0) basis.push_back(c);
  }
  auto mixture = [&](double scale) {  // scale x a random mixture of the basis, norm ~ scale
    std::vector<double> m(dim, 0.0);
    if (basis.empty() || scale <= 0) return m;
    const double w = scale / std::sqrt(double(basis.size()));
    for (size_t c : basis) {
      const double z = w * rng.normal();
      for (int d = 0; d < dim; ++d) m[d] += z * contents[c][d];
    }
    return m;
  };
  // Per-view appearance of every concept: its content plus a bias.
  std::vector<std::vector<double>> look(nc);
  for (size_t c = 0; c < nc; ++c) {
    look[c] = mixture(nl.view_bias);
    for (int d = 0; d < dim; ++d) look[c][d] += contents[c][d];
  }
  std::vector<double> hist(np * nc, 0.0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      hist[(size_t(y * gh / H) * gw + size_t(x * gw / W)) * nc + v.concept_id[size_t(y) * W + x]] += 1;
  std::vector<double> raw(np * dim, 0.0), mean(dim, 0.0);
  for (size_t p = 0; p < np; ++p) {
    double total = 0;
    for (size_t c = 0; c < nc; ++c) total += hist[p * nc + c];
    for (size_t c = 0; c < nc; ++c) {
      const double a = hist[p * nc + c] / total;
      if (a == 0) continue;
      for (int d = 0; d < dim; ++d) raw[p * dim + d] += a * look[c][d];
    }
    for (int d = 0; d < dim; ++d) mean[d] += raw[p * dim + d] / double(np);
  }
  const std::vector<float> gI = image_direction(dim);
  const double iso = nl.patch_noise / std::sqrt(double(dim));
  std::vector<float> out(np * dim);
  std::vector<double> o(dim);
  for (int py = 0; py < gh; ++py)
    for (int px = 0; px < gw; ++px) {
      std::fill(o.begin(), o.end(), 0.0);
      double wsum = 0;
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx) {
          const int qy = py + dy, qx = px + dx;
          if (qy < 0 || qy >= gh || qx < 0 || qx >= gw) continue;
          const double wgt = dx == 0 && dy == 0 ? 0.4 : dx == 0 || dy == 0 ? 0.1 : 0.05;
          const double* r = &raw[(size_t(qy) * gw + qx) * dim];
          for (int d = 0; d < dim; ++d) o[d] += wgt * r[d];
          wsum += wgt;
        }
      const std::vector<double> confusion = mixture(nl.confusion);
      double s = 0;
      for (int d = 0; d < dim; ++d) {
        const double content = 0.85 * o[d] / wsum + 0.15 * mean[d] + confusion[d];
        o[d] = kImageShared * gI[d] + kContent * content + iso * rng.normal();
        s += o[d] * o[d];
      }
      float* f = &out[(size_t(py) * gw + px) * dim];
      for (int d = 0; d < dim; ++d) f[d] = static_cast<float>(o[d] / std::sqrt(s));
    }
  return out;
}

}  // namespace hgs::synth
