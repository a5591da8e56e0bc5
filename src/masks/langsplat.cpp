// LangSplat preprocess.py output (<key>_s.npy seg maps, <key>_f.npy mask features) -> label map + feature grid.
// LangSplat paints each level's masks in list order into a [4, h, w] map (-1 = none; later masks overwrite
// earlier ones) and offsets level j's indices by the mask counts of levels 0..j-1, so every index points into the
// concatenated [M, 512] feature list. We keep one level: label = index + 1. The feature grid averages, over
// each stride x stride cell, the features of the cell's labelled pixels (zero where none is labelled).
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <regex>

#include "core/error.h"
#include "core/fs.h"
#include "core/half.h"
#include "core/npy.h"
#include "masks/sources.h"

namespace hgs::masks {
namespace fs = std::filesystem;

std::vector<int64_t> read_npy_integers(const fs::path& file, std::vector<size_t>& shape) {
  const std::string name = file.string();
  auto b = read_file_bytes(file);
  if (b.size() < 10 || b[0] != 0x93 || std::string(b.begin() + 1, b.begin() + 6) != "NUMPY")
    fail("{}: not an NPY file", name);
  size_t hlen, hstart;
  if (b[6] == 1) {
    hlen = b[8] | (b[9] << 8);
    hstart = 10;
  } else if (b[6] == 2 || b[6] == 3) {
    if (b.size() < 12) fail("{}: truncated NPY header", name);
    hlen = b[8] | (b[9] << 8) | (b[10] << 16) | (size_t(b[11]) << 24);
    hstart = 12;
  } else fail("{}: unsupported NPY version {}", name, int(b[6]));
  if (hlen > kMaxNpyHeader) fail("{}: NPY header of {} bytes is too long (at most {})", name, hlen, kMaxNpyHeader);
  if (hstart + hlen > b.size()) fail("{}: truncated NPY header", name);
  const std::string h(reinterpret_cast<const char*>(b.data() + hstart), hlen);
  std::smatch m;
  if (!std::regex_search(h, m, std::regex(R"('descr'\s*:\s*'([<|=]?)([fiu])(\d)')")))
    fail("{}: NPY dtype is not a little-endian integer or float type", name);
  const char kind = std::string(m[2])[0];
  const int bytes = std::stoi(m[3]);
  const bool ok = (kind == 'f' && (bytes == 2 || bytes == 4 || bytes == 8)) ||
                  (kind == 'i' && (bytes == 1 || bytes == 2 || bytes == 4 || bytes == 8)) ||
                  (kind == 'u' && (bytes == 1 || bytes == 2 || bytes == 4));
  if (!ok) fail("{}: unsupported NPY dtype {}{}", name, kind, bytes);
  if (std::regex_search(h, m, std::regex(R"('fortran_order'\s*:\s*True)")))
    fail("{}: Fortran-order NPY arrays are not supported", name);
  if (!std::regex_search(h, m, std::regex(R"('shape'\s*:\s*\(([^)]*)\))"))) fail("{}: NPY header has no 'shape'", name);
  shape = parse_npy_shape(m[1], size_t(bytes), name);  // dimensions and body size checked against overflow
  size_t n = 1;
  for (size_t d : shape) n *= d;
  const size_t off = hstart + hlen;
  if (n * bytes > b.size() - off) fail("{}: truncated NPY body", name);
  std::vector<int64_t> out(n);
  const uint8_t* p = b.data() + off;
  for (size_t i = 0; i < n; ++i, p += bytes) {
    double v;
    if (kind == 'f') {
      if (bytes == 2) v = half_to_float(uint16_t(p[0] | (p[1] << 8)));
      else if (bytes == 4) {
        float f;
        std::memcpy(&f, p, 4);
        v = f;
      } else std::memcpy(&v, p, 8);
      if (!std::isfinite(v) || v != std::floor(v)) fail("{}: element {} is {}, not an integer", name, i, v);
      if (std::abs(v) > 9.0e18) fail("{}: element {} is {}, out of range", name, i, v);  // int64 cast undefined
      out[i] = int64_t(v);
    } else if (kind == 'i') {
      int64_t x = 0;
      std::memcpy(&x, p, bytes);
      if (bytes < 8 && (p[bytes - 1] & 0x80)) x |= -(int64_t(1) << (8 * bytes));  // sign extension
      out[i] = x;
    } else {
      uint64_t x = 0;
      std::memcpy(&x, p, bytes);
      out[i] = int64_t(x);
    }
  }
  return out;
}

LangSplatView read_langsplat(const fs::path& seg_file, const fs::path& feat_file, int level, int width, int height,
                             int stride) {
  std::vector<size_t> shape;
  const std::vector<int64_t> seg = read_npy_integers(seg_file, shape);
  if (shape.size() != 3)
    fail("{}: seg map must be [levels, h, w], found {} dimensions", seg_file.string(), shape.size());
  const int L = int(shape[0]), h = int(shape[1]), w = int(shape[2]);
  if (level >= L) fail("{}: has {} levels, level {} asked", seg_file.string(), L, level);
  if (h <= 0 || w <= 0) fail("{}: empty seg map", seg_file.string());
  // LangSplat may have resized the image (to 1080 lines by default); accept the same aspect ratio.
  if (std::abs(double(w) / h - double(width) / height) > 0.02 * double(width) / height)
    fail("{}: seg map is {}x{} but the image is {}x{} (a different aspect ratio)", seg_file.string(), w, h, width,
         height);
  NpyArray f = read_npy(feat_file);
  if (f.shape.size() != 2) fail("{}: features must be [M, D], found {} dimensions", feat_file.string(), f.shape.size());
  if (f.dtype != DType::F32 && f.dtype != DType::F16)
    fail("{}: features must be float16 or float32", feat_file.string());
  const int M = int(f.shape[0]), D = int(f.shape[1]);
  if (D <= 0) fail("{}: features have dimension 0", feat_file.string());
  if (M + 1 > 65535) fail("{}: {} masks do not fit in a 16-bit label map", feat_file.string(), M);
  const std::vector<float> feat = f.to_float();
  const int64_t* lv = seg.data() + size_t(level) * h * w;  // [h, w]
  for (size_t p = 0; p < size_t(h) * w; ++p)
    if (lv[p] < -1 || lv[p] >= M)
      fail("{}: index {} at pixel ({}, {}) of level {} is beyond the feature list ({} has {} masks)", seg_file.string(),
           lv[p], p % w, p / w, level, feat_file.string(), M);
  LangSplatView out;
  out.num_masks = M;
  out.dim = D;
  out.labels = LabelMap(width, height);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      const int sx = std::min(w - 1, int((x + 0.5) * w / width)), sy = std::min(h - 1, int((y + 0.5) * h / height));
      out.labels.at(x, y) = uint16_t(lv[size_t(sy) * w + sx] + 1);
    }
  out.grid_h = (h + stride - 1) / stride;
  out.grid_w = (w + stride - 1) / stride;
  out.grid.assign(size_t(out.grid_h) * out.grid_w * D, 0.f);
  for (int gy = 0; gy < out.grid_h; ++gy)
    for (int gx = 0; gx < out.grid_w; ++gx) {
      std::map<int64_t, int> count;
      int n = 0;
      for (int y = gy * stride; y < std::min(h, (gy + 1) * stride); ++y)
        for (int x = gx * stride; x < std::min(w, (gx + 1) * stride); ++x) {
          const int64_t l = lv[size_t(y) * w + x];
          if (l >= 0) {
            count[l]++;
            ++n;
          }
        }
      if (!n) continue;
      float* g = &out.grid[(size_t(gy) * out.grid_w + gx) * D];
      for (auto [l, c] : count) {
        const float a = float(c) / float(n);
        const float* src = &feat[size_t(l) * D];
        for (int d = 0; d < D; ++d) g[d] += a * src[d];
      }
    }
  return out;
}

}  // namespace hgs::masks
