// SAM pre- / post-processing: see resample.h and model.h (preprocess, upscale_masks).
#include "sam/resample.h"

#include <algorithm>

#include "core/error.h"
#include "nn/resize.h"
#include "nn/thread_pool.h"
#include "sam/model.h"

namespace hgs::sam {
namespace {

constexpr float kMean[3] = {0.485f, 0.456f, 0.406f};
constexpr float kStd[3] = {0.229f, 0.224f, 0.225f};

struct Lin {
  std::vector<int> i0, i1;
  std::vector<float> l1;  // weight of i1 (i0 gets 1 - l1)
};

// torch's linear source indices for `in` -> `out` samples (align_corners false). The source position is computed
// in double and only the weight rounded to float: in float, (o + 0.5) * in / out loses ~1e-7 of the position,
// which at positions ~40 (the crop's upsampling to the image size) is ~2e-6 of the weight; this matches torch's
// results to a few ulp (observed 6e-7 against 2.6e-6 with float positions).
Lin lin_taps(int in, int out) {
  Lin t;
  t.i0.resize(out);
  t.i1.resize(out);
  t.l1.resize(out);
  const double scale = double(in) / double(out);
  for (int o = 0; o < out; ++o) {
    const double s = std::max((o + 0.5) * scale - 0.5, 0.0);
    int i = std::min(int(s), in - 1);
    t.i0[o] = i;
    t.i1[o] = std::min(i + 1, in - 1);
    t.l1[o] = float(s - double(i));
  }
  return t;
}

}  // namespace

void preprocess_shape(int h, int w, int longest, int* oh, int* ow) {
  const double s = double(longest) / double(std::max(h, w));
  *oh = int(h * s + 0.5);
  *ow = int(w * s + 0.5);
}

std::vector<float> resize_planes_bilinear(const float* src, int n, int h, int w, int ch, int cw, int oh, int ow,
                                          int keep_h, int keep_w) {
  if (ch <= 0 || cw <= 0 || ch > h || cw > w || oh <= 0 || ow <= 0 || keep_h > oh || keep_w > ow)
    fail("bilinear resize: bad sizes ({}x{} crop of {}x{} -> {}x{})", cw, ch, w, h, ow, oh);
  const Lin tx = lin_taps(cw, ow), ty = lin_taps(ch, oh);
  const int rows = keep_h > 0 ? keep_h : oh, cols = keep_w > 0 ? keep_w : ow;
  std::vector<float> out(size_t(n) * rows * cols);
  nn::parallel_for(long(n) * rows, 16, [&](long r0, long r1) {
    for (long r = r0; r < r1; ++r) {
      const int p = int(r / rows), y = int(r % rows);
      const float* a = src + (size_t(p) * h + ty.i0[y]) * w;
      const float* b = src + (size_t(p) * h + ty.i1[y]) * w;
      const float ly = ty.l1[y];
      float* o = out.data() + size_t(r) * cols;
      for (int x = 0; x < cols; ++x) {
        const int x0 = tx.i0[x], x1 = tx.i1[x];
        const float lx = tx.l1[x];
        const float top = (1 - lx) * a[x0] + lx * a[x1], bot = (1 - lx) * b[x0] + lx * b[x1];
        o[x] = (1 - ly) * top + ly * bot;
      }
    }
  });
  return out;
}

std::vector<float> SamModel::preprocess(const Image& img, int* input_h, int* input_w) const {
  if (img.channels != 3) fail("SAM preprocessing needs an RGB image ({} channels given)", img.channels);
  if (img.width <= 0 || img.height <= 0) fail("SAM preprocessing: empty image");
  const int S = image_size();
  int h, w;
  preprocess_shape(img.height, img.width, S, &h, &w);
  std::vector<float> r = (h == img.height && w == img.width)
                             ? img.px
                             : nn::resize_aa(img.px.data(), img.height, img.width, 3, h, w, nn::AaFilter::Bilinear);
  std::vector<float> out(size_t(S) * S * 3, 0.f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c)
        out[(size_t(y) * S + x) * 3 + c] = (r[(size_t(y) * w + x) * 3 + c] - kMean[c]) / kStd[c];
  if (input_h) *input_h = h;
  if (input_w) *input_w = w;
  return out;
}

std::vector<float> SamModel::upscale_masks(const ImageEmbedding& e, const float* lowres, int n) const {
  const int s = 4 * vision.grid, S = image_size();
  // Only the part of the S x S upsampling that the crop keeps.
  std::vector<float> crop = resize_planes_bilinear(lowres, n, s, s, s, s, S, S, e.input_h, e.input_w);
  return resize_planes_bilinear(crop.data(), n, e.input_h, e.input_w, e.input_h, e.input_w, e.orig_h, e.orig_w);
}

}  // namespace hgs::sam
