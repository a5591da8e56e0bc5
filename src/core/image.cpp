#include "core/image.h"

#include <stb/stb_image.h>
#include <zlib.h>

#include <algorithm>
#include <cctype>
#include <cstring>
#include <string>

#include "core/error.h"
#include "core/fs.h"

namespace hgs {

namespace {
// Sizes from an image header are checked before anything is allocated by them: a PNG of a few bytes may claim
// 2^24 x 2^24 pixels (stb's own limit), which decoding would try to allocate.
constexpr int64_t kMaxImagePixels = int64_t(1) << 28;  // 268 megapixels (1 GiB as floats per channel)

// A PNG's chunk lengths against the bytes that follow them: stb_image reserves memory for a chunk's stated
// length before reading it, so a 239-byte file claiming a 2 GB chunk had it allocate 2 GB (fuzz_image).
void check_png_chunks(const std::vector<uint8_t>& bytes, const std::filesystem::path& path) {
  static const uint8_t sig[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n'};
  if (bytes.size() < 8 || std::memcmp(bytes.data(), sig, 8) != 0) return;
  size_t pos = 8;
  while (pos + 8 <= bytes.size()) {
    const uint32_t len = uint32_t(bytes[pos]) << 24 | uint32_t(bytes[pos + 1]) << 16 | uint32_t(bytes[pos + 2]) << 8 |
                         uint32_t(bytes[pos + 3]);
    const size_t left = bytes.size() - pos - 8;  // after the length and the type
    std::string type(reinterpret_cast<const char*>(bytes.data() + pos + 4), 4);
    for (char& ch : type)
      if (!std::isalpha(static_cast<unsigned char>(ch))) ch = '?';
    if (size_t(len) + 4 > left)  // data + CRC
      fail("{}: PNG chunk '{}' at byte {} claims {} bytes but only {} follow (truncated or corrupt file)",
           path.string(), type, pos, len, left >= 4 ? left - 4 : 0);
    if (type == "IEND") return;
    pos += 12 + size_t(len);
  }
}

void check_header_size(const std::vector<uint8_t>& bytes, const std::filesystem::path& path) {
  int w = 0, h = 0, c = 0;
  if (stbi_info_from_memory(bytes.data(), static_cast<int>(bytes.size()), &w, &h, &c) &&
      (w < 1 || h < 1 || int64_t(w) * h > kMaxImagePixels))
    fail("{}: image of {}x{} pixels is too large (at most {} pixels)", path.string(), w, h, kMaxImagePixels);
  check_png_chunks(bytes, path);  // (when the header cannot be read, decoding says why)
}
}  // namespace

Image load_image(const std::filesystem::path& path, int channels) {
  auto bytes = read_file_bytes(path);
  check_header_size(bytes, path);
  int w, h, c;
  const bool is16 = stbi_is_16_bit_from_memory(bytes.data(), static_cast<int>(bytes.size()));
  Image img;
  if (is16) {
    uint16_t* p = stbi_load_16_from_memory(bytes.data(), static_cast<int>(bytes.size()), &w, &h, &c, channels);
    if (!p) fail("{}: cannot decode image ({})", path.string(), stbi_failure_reason());
    img = Image(w, h, channels);
    for (size_t i = 0; i < img.px.size(); ++i) img.px[i] = p[i] / 65535.f;
    stbi_image_free(p);
  } else {
    uint8_t* p = stbi_load_from_memory(bytes.data(), static_cast<int>(bytes.size()), &w, &h, &c, channels);
    if (!p) fail("{}: cannot decode image ({})", path.string(), stbi_failure_reason());
    img = Image(w, h, channels);
    for (size_t i = 0; i < img.px.size(); ++i) img.px[i] = p[i] * (1.f / 255.f);
    stbi_image_free(p);
  }
  return img;
}

void image_size(const std::filesystem::path& path, int& width, int& height) {
  int c;
  if (!std::filesystem::exists(path)) fail("{}: file not found", path.string());
  if (!stbi_info(path.c_str(), &width, &height, &c))
    fail("{}: cannot read image header ({})", path.string(), stbi_failure_reason());
}

LabelMap load_label_png(const std::filesystem::path& path) {
  auto bytes = read_file_bytes(path);
  check_header_size(bytes, path);
  int w, h, c;
  if (!stbi_info_from_memory(bytes.data(), static_cast<int>(bytes.size()), &w, &h, &c))
    fail("{}: cannot decode label PNG ({})", path.string(), stbi_failure_reason());
  if (c != 1)
    fail("{}: label map must be a single-channel (greyscale) 8- or 16-bit PNG, found {} channels", path.string(), c);
  LabelMap m(w, h);
  if (stbi_is_16_bit_from_memory(bytes.data(), static_cast<int>(bytes.size()))) {
    uint16_t* p = stbi_load_16_from_memory(bytes.data(), static_cast<int>(bytes.size()), &w, &h, &c, 1);
    if (!p) fail("{}: cannot decode label PNG ({})", path.string(), stbi_failure_reason());
    std::memcpy(m.v.data(), p, m.v.size() * 2);
    stbi_image_free(p);
  } else {
    uint8_t* p = stbi_load_from_memory(bytes.data(), static_cast<int>(bytes.size()), &w, &h, &c, 1);
    if (!p) fail("{}: cannot decode label PNG ({})", path.string(), stbi_failure_reason());
    for (size_t i = 0; i < m.v.size(); ++i) m.v[i] = p[i];
    stbi_image_free(p);
  }
  return m;
}

namespace {
void put_be32(std::vector<uint8_t>& o, uint32_t v) {
  o.push_back(v >> 24);
  o.push_back((v >> 16) & 255);
  o.push_back((v >> 8) & 255);
  o.push_back(v & 255);
}
void put_chunk(std::vector<uint8_t>& o, const char* type, const uint8_t* data, size_t n) {
  put_be32(o, static_cast<uint32_t>(n));
  size_t start = o.size();
  o.insert(o.end(), type, type + 4);
  if (n) o.insert(o.end(), data, data + n);
  uLong crc = crc32(0L, o.data() + start, static_cast<uInt>(n + 4));
  put_be32(o, static_cast<uint32_t>(crc));
}
}  // namespace

std::vector<uint8_t> encode_png(int width, int height, int channels, int bit_depth, const void* data) {
  const int bpp = channels * bit_depth / 8;
  const size_t row = size_t(width) * bpp;
  std::vector<uint8_t> raw((row + 1) * height);
  const uint8_t* src = static_cast<const uint8_t*>(data);
  for (int y = 0; y < height; ++y) {
    uint8_t* dst = &raw[y * (row + 1)];
    dst[0] = 0;  // filter: none
    if (bit_depth == 8) {
      std::memcpy(dst + 1, src + y * row, row);
    } else {  // PNG stores 16-bit samples big endian
      const uint16_t* s16 = reinterpret_cast<const uint16_t*>(src + y * row);
      for (size_t i = 0; i < row / 2; ++i) {
        dst[1 + 2 * i] = s16[i] >> 8;
        dst[2 + 2 * i] = s16[i] & 255;
      }
    }
  }
  uLongf zlen = compressBound(static_cast<uLong>(raw.size()));
  std::vector<uint8_t> z(zlen);
  if (compress2(z.data(), &zlen, raw.data(), static_cast<uLong>(raw.size()), 6) != Z_OK) fail("PNG compression failed");
  z.resize(zlen);
  std::vector<uint8_t> o = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  uint8_t ihdr[13];
  auto be = [](uint8_t* p, uint32_t v) {
    p[0] = v >> 24;
    p[1] = (v >> 16) & 255;
    p[2] = (v >> 8) & 255;
    p[3] = v & 255;
  };
  be(ihdr, width);
  be(ihdr + 4, height);
  ihdr[8] = static_cast<uint8_t>(bit_depth);
  ihdr[9] = channels == 1 ? 0 : channels == 2 ? 4 : channels == 3 ? 2 : 6;
  ihdr[10] = ihdr[11] = ihdr[12] = 0;
  put_chunk(o, "IHDR", ihdr, 13);
  put_chunk(o, "IDAT", z.data(), z.size());
  put_chunk(o, "IEND", nullptr, 0);
  return o;
}

void save_png(const std::filesystem::path& path, const Image& img) {
  if (img.channels < 1 || img.channels > 4)
    fail("{}: cannot save a {}-channel image as PNG", path.string(), img.channels);
  std::vector<uint8_t> b(img.px.size());
  for (size_t i = 0; i < b.size(); ++i) b[i] = static_cast<uint8_t>(std::clamp(img.px[i], 0.f, 1.f) * 255.f + 0.5f);
  auto png = encode_png(img.width, img.height, img.channels, 8, b.data());
  atomic_write_bytes(path, png.data(), png.size());
}

void save_label_png(const std::filesystem::path& path, const LabelMap& labels) {
  uint16_t mx = labels.v.empty() ? 0 : *std::max_element(labels.v.begin(), labels.v.end());
  std::vector<uint8_t> png;
  if (mx <= 255) {
    std::vector<uint8_t> b(labels.v.begin(), labels.v.end());
    png = encode_png(labels.width, labels.height, 1, 8, b.data());
  } else {
    png = encode_png(labels.width, labels.height, 1, 16, labels.v.data());
  }
  atomic_write_bytes(path, png.data(), png.size());
}

Image downscale_area(const Image& img, int f) {
  if (f <= 1) return img;
  Image o(img.width / f, img.height / f, img.channels);
  const float inv = 1.f / float(f * f);
  for (int y = 0; y < o.height; ++y)
    for (int x = 0; x < o.width; ++x)
      for (int c = 0; c < img.channels; ++c) {
        float s = 0;
        for (int dy = 0; dy < f; ++dy)
          for (int dx = 0; dx < f; ++dx) s += img.at(x * f + dx, y * f + dy, c);
        o.at(x, y, c) = s * inv;
      }
  return o;
}

LabelMap downscale_labels(const LabelMap& labels, int f) {
  if (f <= 1) return labels;
  LabelMap o(labels.width / f, labels.height / f);
  for (int y = 0; y < o.height; ++y)
    for (int x = 0; x < o.width; ++x) o.at(x, y) = labels.at(x * f + f / 2, y * f + f / 2);
  return o;
}

}  // namespace hgs
