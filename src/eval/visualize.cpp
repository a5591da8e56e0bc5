// Overlays and heatmaps. The contour is the ground truth minus its 3x3 erosion applied `thickness` times, with
// the image exterior counted as inside so that masks touching the border get no line along it.
#include "eval/visualize.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace hgs::eval {

namespace {

// Turbo sampled at t = i / 16 from the polynomial approximation (see visualize.h).
constexpr float kTurbo[17][3] = {{0.1357f, 0.0914f, 0.1067f}, {0.2875f, 0.2441f, 0.6857f}, {0.2686f, 0.4148f, 0.9348f},
                                 {0.1970f, 0.5855f, 0.9699f}, {0.1483f, 0.7405f, 0.8807f}, {0.1624f, 0.8664f, 0.7332f},
                                 {0.2504f, 0.9528f, 0.5729f}, {0.4012f, 0.9925f, 0.4282f}, {0.5885f, 0.9819f, 0.3132f},
                                 {0.7775f, 0.9209f, 0.2310f}, {0.9316f, 0.8139f, 0.1771f}, {1.0000f, 0.6697f, 0.1418f},
                                 {1.0000f, 0.5017f, 0.1140f}, {0.9349f, 0.3288f, 0.0842f}, {0.7864f, 0.1749f, 0.0473f},
                                 {0.6315f, 0.0701f, 0.0062f}, {0.5659f, 0.0504f, 0.0000f}};

}  // namespace

Rgb turbo(float t) {
  if (std::isnan(t)) t = 0.f;
  t = std::clamp(t, 0.f, 1.f) * 16.f;
  const int i = std::min(15, static_cast<int>(t));
  const float f = t - float(i);
  Rgb c;
  for (int k = 0; k < 3; ++k) c[k] = kTurbo[i][k] + f * (kTurbo[i + 1][k] - kTurbo[i][k]);
  return c;
}

Image heatmap(const std::vector<float>& v, int width, int height, float lo, float hi) {
  if (width <= 0 || height <= 0 || v.size() != size_t(width) * height)
    fail("eval: heatmap input holds {} values, expected {}x{}", v.size(), width, height);
  if (!(lo < hi)) {
    lo = std::numeric_limits<float>::infinity();
    hi = -lo;
    for (float x : v)
      if (std::isfinite(x)) {
        lo = std::min(lo, x);
        hi = std::max(hi, x);
      }
    if (!(lo < hi)) hi = lo + 1.f;  // constant (or all non-finite): t = 0
  }
  Image out(width, height, 3);
  const float inv = 1.f / (hi - lo);
  for (size_t i = 0; i < v.size(); ++i) {
    const Rgb c = turbo((v[i] - lo) * inv);
    for (int k = 0; k < 3; ++k) out.px[i * 3 + k] = c[k];
  }
  return out;
}

void save_heatmap_png(const std::filesystem::path& path, const std::vector<float>& v, int width, int height, float lo,
                      float hi) {
  save_png(path, heatmap(v, width, height, lo, hi));
}

Image overlay(const Image& img, const Mask& pred, const Mask& gt, const OverlayStyle& style) {
  const int W = img.width, H = img.height;
  const size_t n = size_t(W) * H;
  if (img.channels != 1 && img.channels != 3 && img.channels != 4)
    fail("eval: overlay needs a 1-, 3- or 4-channel image, got {}", img.channels);
  if (pred.size() != n) fail("eval: overlay mask holds {} pixels, expected {}x{}", pred.size(), W, H);
  if (!gt.empty() && gt.size() != n)
    fail("eval: overlay ground truth holds {} pixels, expected {}x{}", gt.size(), W, H);
  Image out(W, H, 3);
  for (size_t i = 0; i < n; ++i)
    for (int k = 0; k < 3; ++k) {
      float v = img.px[i * img.channels + (img.channels == 1 ? 0 : k)];
      if (pred[i]) v = (1.f - style.alpha) * v + style.alpha * style.tint[k];
      out.px[i * 3 + k] = v;
    }
  if (!gt.empty() && style.thickness > 0) {
    const Mask er = erode3x3(gt, W, H, style.thickness, 1);
    for (size_t i = 0; i < n; ++i)
      if (gt[i] && !er[i])
        for (int k = 0; k < 3; ++k) out.px[i * 3 + k] = style.contour[k];
  }
  return out;
}

void save_overlay_png(const std::filesystem::path& path, const Image& img, const Mask& pred, const Mask& gt,
                      const OverlayStyle& style) {
  save_png(path, overlay(img, pred, gt, style));
}

Rgb class_color(int c) {
  double h = std::fmod(c * 0.6180339887498949, 1.0) * 6.0;
  const double s = 0.75, v = (c % 2) ? 0.7 : 0.95;
  const int i = static_cast<int>(h) % 6;
  const double f = h - std::floor(h), p = v * (1 - s), q = v * (1 - s * f), t = v * (1 - s * (1 - f));
  double r, g, b;
  switch (i) {
    case 0:
      r = v;
      g = t;
      b = p;
      break;
    case 1:
      r = q;
      g = v;
      b = p;
      break;
    case 2:
      r = p;
      g = v;
      b = t;
      break;
    case 3:
      r = p;
      g = q;
      b = v;
      break;
    case 4:
      r = t;
      g = p;
      b = v;
      break;
    default:
      r = v;
      g = p;
      b = q;
      break;
  }
  return {float(r), float(g), float(b)};
}

Image class_overlay(const Image& img, const std::vector<uint16_t>& classes, float alpha) {
  const size_t n = size_t(img.width) * img.height;
  if (img.channels != 1 && img.channels != 3 && img.channels != 4)
    fail("eval: class overlay needs a 1-, 3- or 4-channel image, got {}", img.channels);
  if (classes.size() != n)
    fail("eval: class map holds {} pixels, expected {}x{}", classes.size(), img.width, img.height);
  Image out(img.width, img.height, 3);
  for (size_t i = 0; i < n; ++i) {
    const Rgb c = class_color(classes[i]);
    for (int k = 0; k < 3; ++k)
      out.px[i * 3 + k] = (1.f - alpha) * img.px[i * img.channels + (img.channels == 1 ? 0 : k)] + alpha * c[k];
  }
  return out;
}

void save_mask_png(const std::filesystem::path& path, const Mask& m, int width, int height) {
  if (width <= 0 || height <= 0 || m.size() != size_t(width) * height)
    fail("eval: mask holds {} pixels, expected {}x{}", m.size(), width, height);
  Image img(width, height, 1);
  for (size_t i = 0; i < m.size(); ++i) img.px[i] = m[i] ? 1.f : 0.f;
  save_png(path, img);
}

}  // namespace hgs::eval
