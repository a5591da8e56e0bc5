// PNG decoding to raw sample values (palette index or grey level); see png_index.h.
#include "masks/png_index.h"

#include <zlib.h>

#include <algorithm>
#include <cstdlib>
#include <cstring>
#include <string>

#include "core/error.h"
#include "core/fs.h"

namespace hgs::masks {
namespace {

uint32_t be32(const uint8_t* p) { return uint32_t(p[0]) << 24 | uint32_t(p[1]) << 16 | uint32_t(p[2]) << 8 | p[3]; }

void put_be32(std::vector<uint8_t>& o, uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) o.push_back(uint8_t(v >> s));
}

void put_chunk(std::vector<uint8_t>& o, const char* type, const uint8_t* data, size_t n) {
  put_be32(o, uint32_t(n));
  const size_t start = o.size();
  o.insert(o.end(), type, type + 4);
  if (n) o.insert(o.end(), data, data + n);
  put_be32(o, uint32_t(crc32(0L, o.data() + start, uInt(n + 4))));
}

int paeth(int a, int b, int c) {
  const int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  return (pa <= pb && pa <= pc) ? a : pb <= pc ? b : c;
}

}  // namespace

LabelMap decode_index_png(const uint8_t* b, size_t size, const std::string& name) {
  static const uint8_t sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (size < 8 || std::memcmp(b, sig, 8) != 0) fail("{}: not a PNG file", name);
  size_t p = 8;
  int w = 0, h = 0, depth = 0, ctype = -1, interlace = 0;
  bool have_plte = false, have_ihdr = false, have_iend = false;
  std::vector<uint8_t> idat;
  while (p + 12 <= size) {
    const uint32_t len = be32(b + p);
    if (len > size - p - 12) fail("{}: truncated PNG chunk", name);
    const std::string type(reinterpret_cast<const char*>(b + p + 4), 4);
    const uint8_t* data = b + p + 8;
    if (be32(data + len) != uint32_t(crc32(0L, b + p + 4, uInt(len + 4))))
      fail("{}: corrupt PNG (CRC of chunk {} is wrong)", name, type);
    if (type == "IHDR") {
      if (len != 13) fail("{}: corrupt PNG (IHDR has {} bytes)", name, len);
      w = int(be32(data));
      h = int(be32(data + 4));
      depth = data[8];
      ctype = data[9];
      interlace = data[12];
      have_ihdr = true;
    } else if (type == "PLTE") {
      have_plte = true;
    } else if (type == "IDAT") {
      idat.insert(idat.end(), data, data + len);
    } else if (type == "IEND") {
      have_iend = true;
      break;
    }
    p += 12 + size_t(len);
  }
  if (!have_ihdr) fail("{}: corrupt PNG (no IHDR chunk)", name);
  if (!have_iend) fail("{}: truncated PNG (no IEND chunk)", name);
  if (w <= 0 || h <= 0 || w > (1 << 20) || h > (1 << 20)) fail("{}: PNG size {}x{} is not valid", name, w, h);
  if (ctype == 2 || ctype == 6)
    fail("{}: colour PNG ({}): a label map must be a palette (indexed) or greyscale PNG", name,
         ctype == 2 ? "RGB" : "RGBA");
  if (ctype == 4) fail("{}: grey+alpha PNG: a label map must be a palette (indexed) or greyscale PNG", name);
  if (ctype != 0 && ctype != 3) fail("{}: PNG colour type {} is not valid", name, ctype);
  if (ctype == 3 && !have_plte) fail("{}: palette PNG without a palette (no PLTE chunk)", name);
  const bool depth_ok = ctype == 3 ? (depth == 1 || depth == 2 || depth == 4 || depth == 8)
                                   : (depth == 1 || depth == 2 || depth == 4 || depth == 8 || depth == 16);
  if (!depth_ok) fail("{}: PNG bit depth {} is not valid for colour type {}", name, depth, ctype);
  if (interlace) fail("{}: interlaced PNGs are not supported as label maps (save it without interlacing)", name);
  const size_t row = (size_t(w) * depth + 7) / 8;
  std::vector<uint8_t> raw((row + 1) * h);
  uLongf out_len = uLongf(raw.size());
  if (uncompress(raw.data(), &out_len, idat.data(), uLong(idat.size())) != Z_OK || out_len != raw.size())
    fail("{}: corrupt PNG (image data does not inflate to {}x{} pixels)", name, w, h);
  const int bpp = std::max(1, depth / 8);  // bytes per complete pixel (1 sample)
  std::vector<uint8_t> prev(row, 0);
  LabelMap m(w, h);
  for (int y = 0; y < h; ++y) {
    uint8_t* r = &raw[y * (row + 1)];
    const int filter = r[0];
    uint8_t* cur = r + 1;
    for (size_t i = 0; i < row; ++i) {
      const int a = i >= size_t(bpp) ? cur[i - bpp] : 0, up = prev[i], c = i >= size_t(bpp) ? prev[i - bpp] : 0;
      switch (filter) {
        case 0: break;
        case 1: cur[i] = uint8_t(cur[i] + a); break;
        case 2: cur[i] = uint8_t(cur[i] + up); break;
        case 3: cur[i] = uint8_t(cur[i] + ((a + up) >> 1)); break;
        case 4: cur[i] = uint8_t(cur[i] + paeth(a, up, c)); break;
        default: fail("{}: corrupt PNG (scanline filter {} in row {})", name, filter, y);
      }
    }
    for (int x = 0; x < w; ++x) {
      uint16_t v;
      if (depth == 16) v = uint16_t(cur[2 * x] << 8 | cur[2 * x + 1]);
      else if (depth == 8) v = cur[x];
      else {
        const int per = 8 / depth, shift = 8 - depth * (x % per + 1);
        v = (cur[x / per] >> shift) & ((1 << depth) - 1);
      }
      m.at(x, y) = v;
    }
    std::memcpy(prev.data(), cur, row);
  }
  return m;
}

LabelMap load_index_png(const std::filesystem::path& path) {
  auto bytes = read_file_bytes(path);
  return decode_index_png(bytes.data(), bytes.size(), path.string());
}

std::vector<uint8_t> encode_palette_png(const LabelMap& labels, const std::vector<uint8_t>& palette_rgb) {
  std::vector<uint8_t> raw;
  raw.reserve(size_t(labels.width + 1) * labels.height);
  for (int y = 0; y < labels.height; ++y) {
    raw.push_back(0);
    for (int x = 0; x < labels.width; ++x) {
      const uint16_t l = labels.at(x, y);
      if (l > 255) fail("palette PNG: label {} does not fit in 8 bits", l);
      raw.push_back(uint8_t(l));
    }
  }
  uLongf zlen = compressBound(uLong(raw.size()));
  std::vector<uint8_t> z(zlen);
  if (compress2(z.data(), &zlen, raw.data(), uLong(raw.size()), 6) != Z_OK) fail("PNG compression failed");
  z.resize(zlen);
  std::vector<uint8_t> o = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  std::vector<uint8_t> ihdr;
  put_be32(ihdr, uint32_t(labels.width));
  put_be32(ihdr, uint32_t(labels.height));
  ihdr.insert(ihdr.end(), {8, 3, 0, 0, 0});
  put_chunk(o, "IHDR", ihdr.data(), ihdr.size());
  if (!palette_rgb.empty()) put_chunk(o, "PLTE", palette_rgb.data(), palette_rgb.size());
  put_chunk(o, "IDAT", z.data(), z.size());
  put_chunk(o, "IEND", nullptr, 0);
  return o;
}

}  // namespace hgs::masks
