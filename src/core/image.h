// Images in memory and on disk. Colour images are float [H, W, C] in [0, 1]; label maps are uint16 [H, W].
// Loading goes through stb_image (PNG 8/16-bit, JPEG); writing PNG uses our own small encoder on zlib
// because stb_image_write cannot write 16-bit PNGs (label maps with more than 255 objects need them).
#pragma once
#include <cstdint>
#include <filesystem>
#include <vector>

namespace hgs {

struct Image {
  int width = 0, height = 0, channels = 0;
  std::vector<float> px;  // [H, W, C], row-major, values in [0, 1]

  Image() = default;
  Image(int w, int h, int c, float fill = 0.f) : width(w), height(h), channels(c), px(size_t(w) * h * c, fill) {}
  float& at(int x, int y, int c = 0) { return px[(size_t(y) * width + x) * channels + c]; }
  float at(int x, int y, int c = 0) const { return px[(size_t(y) * width + x) * channels + c]; }
  bool empty() const { return px.empty(); }
};

struct LabelMap {
  int width = 0, height = 0;
  std::vector<uint16_t> v;  // [H, W]

  LabelMap() = default;
  LabelMap(int w, int h, uint16_t fill = 0) : width(w), height(h), v(size_t(w) * h, fill) {}
  uint16_t& at(int x, int y) { return v[size_t(y) * width + x]; }
  uint16_t at(int x, int y) const { return v[size_t(y) * width + x]; }
};

// Loads an image as `channels` channels (1, 3 or 4); grey is replicated, alpha dropped or set to 1.
Image load_image(const std::filesystem::path& path, int channels = 3);
// Reads only the size of an image file (no decoding).
void image_size(const std::filesystem::path& path, int& width, int& height);
// Loads a single-channel 8- or 16-bit PNG as labels. Colour PNGs are rejected with a clear error.
LabelMap load_label_png(const std::filesystem::path& path);

// Writes an 8-bit PNG (channels 1, 3 or 4), values clamped to [0, 1]. Atomic.
void save_png(const std::filesystem::path& path, const Image& img);
// Writes a label map: 8-bit if every label is <= 255, else 16-bit. Atomic.
void save_label_png(const std::filesystem::path& path, const LabelMap& labels);
// Raw PNG encoder: bit depth 8 or 16, channels 1/3/4, `data` row-major (16-bit samples in host order).
std::vector<uint8_t> encode_png(int width, int height, int channels, int bit_depth, const void* data);

// Area-filter downscale by an integer factor: output size floor(W/F) x floor(H/F), each pixel the mean of its
// F x F block.
Image downscale_area(const Image& img, int factor);
// Nearest-neighbour (majority-free) downscale of a label map: takes the block's centre pixel.
LabelMap downscale_labels(const LabelMap& labels, int factor);

}  // namespace hgs
