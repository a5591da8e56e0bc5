// CLIP's image preprocessing: see preprocess.h.
#include "clip/preprocess.h"

#include <cmath>

#include "core/error.h"
#include "nn/resize.h"

namespace hgs::clip {

void clip_normalize(float* x, size_t pixels) {
  for (size_t i = 0; i < pixels; ++i)
    for (int ch = 0; ch < 3; ++ch) x[i * 3 + ch] = (x[i * 3 + ch] - kClipMean[ch]) / kClipStd[ch];
}

std::vector<float> clip_preprocess(const Image& img, int size) {
  if (img.channels != 3) fail("CLIP preprocessing needs an RGB image ({} channels given)", img.channels);
  const int W = img.width, H = img.height;
  if (W <= 0 || H <= 0) fail("CLIP preprocessing: empty image");
  int ow, oh;
  if (W <= H) {
    ow = size;
    oh = int(int64_t(size) * H / W);
  } else {
    oh = size;
    ow = int(int64_t(size) * W / H);
  }
  std::vector<float> r = (ow == W && oh == H) ? img.px : nn::resize_aa(img.px.data(), H, W, 3, oh, ow);
  const int top = int(std::nearbyint((oh - size) / 2.0)), left = int(std::nearbyint((ow - size) / 2.0));
  std::vector<float> out(size_t(size) * size * 3);
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x)
      for (int ch = 0; ch < 3; ++ch)
        out[(size_t(y) * size + x) * 3 + ch] = r[(size_t(y + top) * ow + x + left) * 3 + ch];
  clip_normalize(out.data(), size_t(size) * size);
  return out;
}

}  // namespace hgs::clip
