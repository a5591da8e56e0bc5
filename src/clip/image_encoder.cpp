// CLIP vision encoder: patch embedding (im2col + one sgemm), class token, positional embeddings (bicubic-
// interpolated to the input's grid when it differs from the native one), ln_pre, the transformer, then
//   global:  ln_post(x[cls]) @ proj
//   dense (MaskCLIP): blocks 0 .. L-2 as usual; for the last block only its value path is kept for every patch
//            token: ln_post(out_proj(ln_1(x) Wv + bv)) @ proj — no query/key attention, no residual, no MLP.
// dense_features adds the resizing and, for images with more patches than `max_tokens`, overlapping square
// tiles whose features are averaged where they overlap.
#include <algorithm>
#include <cmath>

#include "clip/block.h"
#include "clip/model.h"
#include "clip/preprocess.h"
#include "core/error.h"
#include "nn/resize.h"
#include "nn/transformer.h"

namespace hgs::clip {

void ClipModel::vision_forward(const float* img, int H, int W, bool dense, std::vector<float>& out) const {
  if (!has_vision) fail("{}: the model has no vision tower", path.string());
  const int p = vision.patch, w = vision.tr.width, D = embed_dim;
  if (H % p || W % p || H <= 0 || W <= 0)
    fail("vision input {}x{} is not a positive multiple of the patch size {}", W, H, p);
  const int gh = H / p, gw = W / p, np = gh * gw, n = np + 1, kk = 3 * p * p;
  // im2col: patches [np, 3 * p * p] in (c, ky, kx) order, matching the conv weight.
  std::vector<float> cols(size_t(np) * kk);
  for (int gy = 0; gy < gh; ++gy)
    for (int gx = 0; gx < gw; ++gx) {
      float* c = cols.data() + (size_t(gy) * gw + gx) * kk;
      for (int ch = 0; ch < 3; ++ch)
        for (int ky = 0; ky < p; ++ky)
          for (int kx = 0; kx < p; ++kx)
            c[(ch * p + ky) * p + kx] = img[((size_t(gy) * p + ky) * W + gx * p + kx) * 3 + ch];
    }
  std::vector<float> x(size_t(n) * w);
  std::copy(vision.cls.begin(), vision.cls.end(), x.begin());  // x[0] = cls, x[1:] = cols Wpatch^T
  nn::linear(vision.patch_embed, cols.data(), np, x.data() + w);
  // Positional embeddings, interpolated to [gh, gw] when needed.
  const float* pos_grid = vision.pos.data() + w;
  std::vector<float> interp;
  if (gh != vision.grid || gw != vision.grid) {
    interp = nn::resize_bicubic(pos_grid, vision.grid, vision.grid, w, gh, gw);
    pos_grid = interp.data();
  }
  for (int j = 0; j < w; ++j) x[j] += vision.pos[j];
  for (size_t i = 0; i < size_t(np) * w; ++i) x[w + i] += pos_grid[i];
  nn::layer_norm(vision.ln_pre, x.data(), n, w, x.data());

  const int L = int(vision.tr.blocks.size());
  Workspace ws;
  ws.reserve(n, w, L ? vision.tr.blocks[0].fc.out : w, n);
  std::vector<Segment> segs{{0, n}};
  for (int l = 0; l < (dense ? L - 1 : L); ++l)
    block_forward(vision.tr.blocks[l], vision.tr.heads, act, segs, false, x.data(), n, ws);
  if (!dense) {
    out.resize(size_t(D));
    nn::layer_norm(vision.ln_post, x.data(), 1, w, ws.h.data());
    nn::matmul(ws.h.data(), 1, w, vision.proj.data(), D, out.data());
    return;
  }
  if (L == 0) fail("{}: dense features need at least one transformer block", path.string());
  const Block& b = vision.tr.blocks[L - 1];
  // Value path for the patch tokens only (rows 1 .. n-1).
  nn::layer_norm(b.ln1, x.data() + w, np, w, ws.h.data());
  nn::linear(vision.last_value, ws.h.data(), np, ws.attn.data());
  nn::linear(b.out, ws.attn.data(), np, ws.h.data());
  nn::layer_norm(vision.ln_post, ws.h.data(), np, w, ws.h.data());
  out.resize(size_t(np) * D);
  nn::matmul(ws.h.data(), np, w, vision.proj.data(), D, out.data());
}

std::vector<float> ClipModel::embed_image_tensor(const float* x, int H, int W, bool normalize) const {
  std::vector<float> out;
  vision_forward(x, H, W, false, out);
  if (normalize) nn::l2_normalize_rows(out.data(), 1, embed_dim);
  return out;
}

std::vector<float> ClipModel::dense_tensor(const float* x, int H, int W) const {
  std::vector<float> out;
  vision_forward(x, H, W, true, out);
  return out;
}

std::vector<float> ClipModel::embed_image(const Image& img) const {
  if (!has_vision) fail("{}: the model has no vision tower", path.string());
  std::vector<float> x = clip_preprocess(img, image_size());
  return embed_image_tensor(x.data(), image_size(), image_size(), true);
}

namespace {

// Tile origins (in patches) covering [0, total) with tiles of `tile` patches and stride tile / 2.
std::vector<int> tile_starts(int total, int tile) {
  if (total <= tile) return {0};
  std::vector<int> s;
  int stride = std::max(1, tile / 2);
  for (int o = 0;; o += stride) {
    if (o + tile >= total) {
      s.push_back(total - tile);
      break;
    }
    s.push_back(o);
  }
  return s;
}

}  // namespace

DenseFeatures ClipModel::dense_features(const Image& img, const DenseOptions& opt) const {
  if (!has_vision) fail("{}: the model has no vision tower", path.string());
  if (img.channels != 3) fail("dense features need an RGB image ({} channels given)", img.channels);
  if (opt.input_size < vision.patch)
    fail("--input-size {} is smaller than the patch size {}", opt.input_size, vision.patch);
  const int p = vision.patch, D = embed_dim;
  const double s = double(opt.input_size) / std::min(img.width, img.height);
  const int gh = std::max(1, int(std::lround(img.height * s / p))),
            gw = std::max(1, int(std::lround(img.width * s / p)));
  const int H = gh * p, W = gw * p;
  std::vector<float> x =
      (H == img.height && W == img.width) ? img.px : nn::resize_aa(img.px.data(), img.height, img.width, 3, H, W);
  clip_normalize(x.data(), size_t(H) * W);

  DenseFeatures f;
  f.h = gh;
  f.w = gw;
  f.dim = D;
  if (gh * gw <= opt.max_tokens) {
    f.data = dense_tensor(x.data(), H, W);
  } else {
    const int tile = std::max(1, (opt.tile_size > 0 ? opt.tile_size : opt.input_size) / p);
    const int th = std::min(tile, gh), tw = std::min(tile, gw);
    f.data.assign(size_t(gh) * gw * D, 0.f);
    std::vector<float> count(size_t(gh) * gw, 0.f), crop(size_t(th) * p * tw * p * 3);
    for (int ty : tile_starts(gh, th))
      for (int tx : tile_starts(gw, tw)) {
        for (int y = 0; y < th * p; ++y)
          std::copy_n(x.data() + ((size_t(ty) * p + y) * W + size_t(tx) * p) * 3, size_t(tw) * p * 3,
                      crop.data() + size_t(y) * tw * p * 3);
        std::vector<float> t = dense_tensor(crop.data(), th * p, tw * p);
        for (int y = 0; y < th; ++y)
          for (int xx = 0; xx < tw; ++xx) {
            size_t cell = size_t(ty + y) * gw + tx + xx;
            count[cell] += 1;
            const float* src = t.data() + (size_t(y) * tw + xx) * D;
            float* dst = f.data.data() + cell * D;
            for (int d = 0; d < D; ++d) dst[d] += src[d];
          }
      }
    for (size_t c = 0; c < count.size(); ++c)
      for (int d = 0; d < D; ++d) f.data[c * D + d] /= count[c];
  }
  if (opt.normalize) nn::l2_normalize_rows(f.data.data(), gh * gw, D);
  return f;
}

}  // namespace hgs::clip
