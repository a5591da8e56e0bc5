// Antialiased and bicubic image resampling: see resize.h.
#include "nn/resize.h"

#include <cmath>

#include "core/error.h"

namespace hgs::nn {
namespace {

struct Taps {
  std::vector<int> start, count;  // per output index
  std::vector<float> w;           // [out, max_count]
  int max_count = 0;
};

float triangle(float x) {
  x = std::fabs(x);
  return x < 1 ? 1 - x : 0;
}

float keys(float x, float a) {
  x = std::fabs(x);
  if (x < 1) return ((a + 2) * x - (a + 3)) * x * x + 1;
  if (x < 2) return (((x - 5) * x + 8) * x - 4) * a;
  return 0;
}

// PIL / torch-antialias taps for resizing `in` samples to `out` (bicubic: support 2, bilinear: support 1).
Taps aa_taps(int in, int out, AaFilter filter) {
  Taps t;
  const bool cubic = filter == AaFilter::Bicubic;
  const double scale = double(in) / out;
  const double fscale = std::max(scale, 1.0);
  const double support = (cubic ? 2.0 : 1.0) * fscale;
  t.max_count = int(std::ceil(support)) * 2 + 1;
  t.start.resize(out);
  t.count.resize(out);
  t.w.assign(size_t(out) * t.max_count, 0.f);
  for (int i = 0; i < out; ++i) {
    const double center = (i + 0.5) * scale;
    int xmin = std::max(int(center - support + 0.5), 0);
    int xmax = std::min(int(center + support + 0.5), in);
    int n = std::min(xmax - xmin, t.max_count);
    double total = 0;
    float* wr = t.w.data() + size_t(i) * t.max_count;
    for (int j = 0; j < n; ++j) {
      const float d = float((j + xmin - center + 0.5) / fscale);
      double v = cubic ? keys(d, -0.5f) : triangle(d);
      wr[j] = float(v);
      total += v;
    }
    if (total != 0)
      for (int j = 0; j < n; ++j) wr[j] = float(wr[j] / total);
    t.start[i] = xmin;
    t.count[i] = n;
  }
  return t;
}

// torch upsample_bicubic2d (align_corners = false): 4 taps with clamped indices, a = -0.75.
Taps cubic_taps(int in, int out) {
  Taps t;
  t.max_count = 4;
  t.start.resize(out);
  t.count.assign(out, 4);
  t.w.resize(size_t(out) * 4);
  const float scale = float(in) / float(out);
  const float A = -0.75f;
  for (int i = 0; i < out; ++i) {
    float src = (i + 0.5f) * scale - 0.5f;
    int idx = int(std::floor(src));
    float f = src - idx;
    float* wr = t.w.data() + size_t(i) * 4;
    wr[0] = ((A * (f + 1) - 5 * A) * (f + 1) + 8 * A) * (f + 1) - 4 * A;
    wr[1] = ((A + 2) * f - (A + 3)) * f * f + 1;
    wr[2] = ((A + 2) * (1 - f) - (A + 3)) * (1 - f) * (1 - f) + 1;
    wr[3] = ((A * (2 - f) - 5 * A) * (2 - f) + 8 * A) * (2 - f) - 4 * A;
    t.start[i] = idx - 1;  // taps idx-1 .. idx+2, clamped when applied
  }
  return t;
}

// Applies horizontal taps then vertical taps. With `clamp`, tap indices are clamped to the valid range
// (torch's bicubic); otherwise they are within range by construction (antialias taps).
std::vector<float> separable(const float* src, int h, int w, int c, int oh, int ow, const Taps& tx, const Taps& ty,
                             bool clamp) {
  std::vector<float> tmp(size_t(h) * ow * c, 0.f), out(size_t(oh) * ow * c, 0.f);
#pragma omp parallel for schedule(static) if (size_t(h) * ow * c > 65536)
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < ow; ++x) {
      float* o = tmp.data() + (size_t(y) * ow + x) * c;
      const float* wr = tx.w.data() + size_t(x) * tx.max_count;
      for (int k = 0; k < tx.count[x]; ++k) {
        int sx = tx.start[x] + k;
        if (clamp) sx = std::min(std::max(sx, 0), w - 1);
        const float* s = src + (size_t(y) * w + sx) * c;
        for (int ch = 0; ch < c; ++ch) o[ch] += wr[k] * s[ch];
      }
    }
#pragma omp parallel for schedule(static) if (size_t(oh) * ow * c > 65536)
  for (int y = 0; y < oh; ++y) {
    const float* wr = ty.w.data() + size_t(y) * ty.max_count;
    float* o = out.data() + size_t(y) * ow * c;
    for (int k = 0; k < ty.count[y]; ++k) {
      int sy = ty.start[y] + k;
      if (clamp) sy = std::min(std::max(sy, 0), h - 1);
      const float* s = tmp.data() + size_t(sy) * ow * c;
      for (size_t i = 0; i < size_t(ow) * c; ++i) o[i] += wr[k] * s[i];
    }
  }
  return out;
}

}  // namespace

std::vector<float> resize_aa(const float* src, int h, int w, int c, int oh, int ow, AaFilter filter) {
  if (h <= 0 || w <= 0 || oh <= 0 || ow <= 0) fail("resize: empty image ({}x{} -> {}x{})", w, h, ow, oh);
  return separable(src, h, w, c, oh, ow, aa_taps(w, ow, filter), aa_taps(h, oh, filter), false);
}

std::vector<float> resize_bicubic(const float* src, int h, int w, int c, int oh, int ow) {
  if (h <= 0 || w <= 0 || oh <= 0 || ow <= 0) fail("resize: empty grid ({}x{} -> {}x{})", w, h, ow, oh);
  return separable(src, h, w, c, oh, ow, cubic_taps(w, ow), cubic_taps(h, oh), true);
}

}  // namespace hgs::nn
