// 8-bit rasters of the input stage (pixels.h): signature sniffing, truncation walks, stb decoding / encoding,
// the EXIF orientations as a source-index map, and a separable area-averaging resize (fractional coverage
// weights, rows then columns).
#include "prepare/pixels.h"

#include <stb/stb_image.h>
#include <stb/stb_image_write.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>

#include "core/error.h"
#include "core/image.h"

namespace hgs::prepare {
namespace fs = std::filesystem;

ImageKind sniff_image(const uint8_t* d, size_t n) {
  if (n >= 3 && d[0] == 0xFF && d[1] == 0xD8 && d[2] == 0xFF) return ImageKind::jpeg;
  if (n >= 4 && d[0] == 0x89 && d[1] == 'P' && d[2] == 'N' && d[3] == 'G') return ImageKind::png;
  return ImageKind::none;
}

ImageKind sniff_image(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) return ImageKind::unreadable;
  uint8_t head[8] = {};
  in.read(reinterpret_cast<char*>(head), sizeof head);
  return sniff_image(head, static_cast<size_t>(in.gcount()));
}

namespace {
bool is_rst(uint8_t m) { return m >= 0xD0 && m <= 0xD7; }

// Index of the marker that ends the entropy-coded data starting at p (FF 00 is a stuffed byte, RSTn is inside).
size_t skip_entropy(const std::vector<uint8_t>& b, size_t p) {
  for (; p + 1 < b.size(); ++p)
    if (b[p] == 0xFF && b[p + 1] != 0x00 && b[p + 1] != 0xFF && !is_rst(b[p + 1])) return p;
  return b.size();
}

// True when the JPEG's markers reach EOI within the bytes (stray bytes between segments tolerated, as decoders do).
bool jpeg_reaches_eoi(const std::vector<uint8_t>& b) {
  const size_t n = b.size();
  size_t p = 2;  // after SOI
  while (p < n) {
    if (b[p] != 0xFF) {
      ++p;
      continue;
    }
    while (p < n && b[p] == 0xFF) ++p;  // fill bytes
    if (p >= n) break;
    const uint8_t m = b[p++];
    if (m == 0xD9) return true;
    if (m == 0x00 || m == 0x01 || is_rst(m)) continue;  // no length
    if (p + 2 > n) break;
    p += size_t(b[p]) << 8 | b[p + 1];
    if (m == 0xDA) p = skip_entropy(b, p);
  }
  return false;
}

bool png_reaches_iend(const std::vector<uint8_t>& b) {
  size_t p = 8;
  while (p + 8 <= b.size()) {
    const size_t len = size_t(b[p]) << 24 | size_t(b[p + 1]) << 16 | size_t(b[p + 2]) << 8 | b[p + 3];
    if (p + 12 + len > b.size()) return false;
    if (std::memcmp(b.data() + p + 4, "IEND", 4) == 0) return true;
    p += 12 + len;
  }
  return false;
}
}  // namespace

std::string incomplete_reason(const std::vector<uint8_t>& bytes, ImageKind kind) {
  if (kind == ImageKind::empty || bytes.empty()) return "empty file (0 bytes: an interrupted copy?)";
  if (kind == ImageKind::jpeg && !jpeg_reaches_eoi(bytes)) return "truncated JPEG (no end marker)";
  if (kind == ImageKind::png && !png_reaches_iend(bytes)) return "truncated PNG (no IEND chunk)";
  return "";
}

std::string image_header_size(const std::vector<uint8_t>& bytes, int& w, int& h) {
  const int n = static_cast<int>(std::min<size_t>(bytes.size(), INT32_MAX));
  int c = 0;
  w = h = 0;
  if (!stbi_info_from_memory(bytes.data(), n, &w, &h, &c))
    return fmt::format("cannot decode image ({})", stbi_failure_reason());
  if (w < 1 || h < 1) return fmt::format("image of {}x{} pixels", w, h);
  return "";
}

std::string decode_rgb(const std::vector<uint8_t>& bytes, Pixels& out, int64_t max_pixels) {
  int w = 0, h = 0, c = 0;
  if (std::string why = image_header_size(bytes, w, h); !why.empty()) return why;
  // From the header, before stb allocates anything: a few KB of JPEG may declare 16383 x 16383 (1.6 GB decoded).
  if (int64_t(w) * h > max_pixels)
    return fmt::format(
        "image of {}x{} pixels ({:.0f} MP) is over the limit of {} pixels (--max-pixels; raise it for a camera "
        "this large)",
        w, h, double(w) * h / 1e6, max_pixels);
  const int n = static_cast<int>(std::min<size_t>(bytes.size(), INT32_MAX));
  uint8_t* p = stbi_load_from_memory(bytes.data(), n, &w, &h, &c, 3);
  if (!p) return fmt::format("cannot decode image ({})", stbi_failure_reason());
  out.width = w;
  out.height = h;
  out.v.assign(p, p + size_t(w) * h * 3);
  stbi_image_free(p);
  return "";
}

namespace {
// The stored pixel (x, y) shown at (dx, dy) of the upright image, per the EXIF orientation table (row 0 / column
// 0 of the stored image is the displayed 1 top/left, 2 top/right, 3 bottom/right, 4 bottom/left, 5 left/top,
// 6 right/top, 7 right/bottom, 8 left/bottom).
void stored_xy(int o, int W, int H, int dx, int dy, int& x, int& y) {
  switch (o) {
    case 2: x = W - 1 - dx, y = dy; break;
    case 3: x = W - 1 - dx, y = H - 1 - dy; break;
    case 4: x = dx, y = H - 1 - dy; break;
    case 5: x = dy, y = dx; break;
    case 6: x = dy, y = H - 1 - dx; break;
    case 7: x = W - 1 - dy, y = H - 1 - dx; break;
    case 8: x = W - 1 - dy, y = dx; break;
    default: x = dx, y = dy;
  }
}
}  // namespace

Pixels apply_orientation(const Pixels& s, int o) {
  if (o < 2 || o > 8) return s;
  Pixels d;
  d.width = o >= 5 ? s.height : s.width;
  d.height = o >= 5 ? s.width : s.height;
  d.v.resize(s.v.size());
  // The source offset is affine in (dx, dy): its origin and its steps along dx and dy.
  auto offset = [&](int dx, int dy) {
    int x, y;
    stored_xy(o, s.width, s.height, dx, dy, x, y);
    return (ptrdiff_t(y) * s.width + x) * 3;
  };
  const ptrdiff_t base = offset(0, 0), step_x = offset(1, 0) - base, step_y = offset(0, 1) - base;
  uint8_t* out = d.v.data();
  for (int dy = 0; dy < d.height; ++dy) {
    const uint8_t* src = s.v.data() + base + dy * step_y;
    for (int dx = 0; dx < d.width; ++dx, src += step_x, out += 3) std::memcpy(out, src, 3);
  }
  return d;
}

bool fit_size(int w, int h, int max_size, int& out_w, int& out_h) {
  out_w = w;
  out_h = h;
  if (max_size <= 0 || std::max(w, h) <= max_size) return false;
  const double s = double(max_size) / std::max(w, h);
  out_w = std::clamp(static_cast<int>(std::lround(w * s)), 1, max_size);
  out_h = std::clamp(static_cast<int>(std::lround(h * s)), 1, max_size);
  return true;
}

namespace {
struct Tap {
  int index;
  float weight;
};
// For each of `out` samples, the input samples its span [i s, (i + 1) s) covers (s = in / out) and the fraction of
// the span each covers (weights sum to 1).
std::vector<std::vector<Tap>> area_taps(int in, int out) {
  const double s = double(in) / out;
  std::vector<std::vector<Tap>> taps(out);
  for (int i = 0; i < out; ++i) {
    const double lo = i * s, hi = std::min<double>(in, (i + 1) * s);
    for (int j = static_cast<int>(lo); j < in && j < hi; ++j) {
      const double cover = std::min<double>(hi, j + 1) - std::max<double>(lo, j);
      if (cover > 1e-9) taps[i].push_back({j, static_cast<float>(cover / (hi - lo))});
    }
  }
  return taps;
}
}  // namespace

Pixels resize_area(const Pixels& src, int width, int height) {
  const auto tx = area_taps(src.width, width), ty = area_taps(src.height, height);
  std::vector<float> rows(size_t(src.height) * width * 3);  // [H_in, W_out, 3]
  for (int y = 0; y < src.height; ++y)
    for (int x = 0; x < width; ++x) {
      float acc[3] = {0, 0, 0};
      for (const Tap& t : tx[x])
        for (int c = 0; c < 3; ++c) acc[c] += t.weight * src.v[(size_t(y) * src.width + t.index) * 3 + c];
      std::copy(acc, acc + 3, rows.begin() + (size_t(y) * width + x) * 3);
    }
  Pixels d;
  d.width = width;
  d.height = height;
  d.v.resize(size_t(width) * height * 3);
  for (int y = 0; y < height; ++y)
    for (int i = 0; i < width * 3; ++i) {
      float acc = 0;
      for (const Tap& t : ty[y]) acc += t.weight * rows[size_t(t.index) * width * 3 + i];
      d.v[size_t(y) * width * 3 + i] = static_cast<uint8_t>(std::clamp(acc + 0.5f, 0.f, 255.f));
    }
  return d;
}

std::vector<uint8_t> encode_jpeg(const Pixels& px, int quality, const std::vector<uint8_t>& exif) {
  std::vector<uint8_t> out;
  auto sink = [](void* ctx, void* data, int size) {
    auto* v = static_cast<std::vector<uint8_t>*>(ctx);
    v->insert(v->end(), static_cast<uint8_t*>(data), static_cast<uint8_t*>(data) + size);
  };
  if (!stbi_write_jpg_to_func(sink, &out, px.width, px.height, 3, px.v.data(), quality))
    fail("cannot encode a {}x{} JPEG", px.width, px.height);
  if (exif.empty() || exif.size() + 2 > 0xFFFF || out.size() < 4) return out;
  size_t at = 2;  // after SOI, and after a JFIF APP0 which must come first
  if (out[2] == 0xFF && out[3] == 0xE0) at = 4 + (size_t(out[4]) << 8 | out[5]);
  const size_t len = exif.size() + 2;
  std::vector<uint8_t> seg = {0xFF, 0xE1, uint8_t(len >> 8), uint8_t(len & 255)};
  seg.insert(seg.end(), exif.begin(), exif.end());
  out.insert(out.begin() + static_cast<ptrdiff_t>(at), seg.begin(), seg.end());
  return out;
}

std::vector<uint8_t> encode_png_rgb(const Pixels& px) { return encode_png(px.width, px.height, 3, 8, px.v.data()); }

}  // namespace hgs::prepare
