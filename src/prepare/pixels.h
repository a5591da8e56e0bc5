// 8-bit RGB rasters of the input stage (photos.cpp, video.cpp): decoding with the checks a photo folder needs
// (JPEG / PNG signature, truncation, size), the 8 EXIF orientations (rotations / flips), area downscaling to a
// longest side, and JPEG / PNG encoding to bytes.
#pragma once
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

namespace hgs::prepare {

struct Pixels {
  int width = 0, height = 0;
  std::vector<uint8_t> v;  // [H, W, 3], row-major RGB
};

// empty: a zero-byte file named like an image (an interrupted copy): unreadable, as a truncated one.
enum class ImageKind { none, jpeg, png, unreadable, empty };

// The kind of image a file holds by its first bytes (JPEG FF D8 FF, PNG 89 'PNG'); none for anything else;
// unreadable when the file cannot be opened.
ImageKind sniff_image(const std::filesystem::path& path);
ImageKind sniff_image(const uint8_t* data, size_t n);

// Why a complete-looking file is not a whole image ("truncated JPEG (no end marker)", "truncated PNG (no IEND
// chunk)"), or "" when it is complete. A JPEG is walked marker by marker (entropy-coded data skipped) up to its
// EOI, so data appended after EOI (motion photos) is accepted; a PNG is walked chunk by chunk up to IEND.
std::string incomplete_reason(const std::vector<uint8_t>& bytes, ImageKind kind);

// The width and height an image's header declares (nothing decoded). Returns "" or the reason it cannot be read.
std::string image_header_size(const std::vector<uint8_t>& bytes, int& width, int& height);

// Decodes to 8-bit RGB (grey replicated, alpha dropped, 16-bit reduced). Returns "" or the reason it failed; an
// image whose header declares more than `max_pixels` pixels is refused before anything is allocated.
std::string decode_rgb(const std::vector<uint8_t>& bytes, Pixels& out, int64_t max_pixels);

// EXIF orientation 1..8 applied: the image as it is meant to be displayed (5..8 swap width and height).
Pixels apply_orientation(const Pixels& src, int orientation);

// The size whose longest side is max_size (aspect kept, rounded) when max(w, h) > max_size > 0. Returns whether
// it differs from w x h.
bool fit_size(int w, int h, int max_size, int& out_w, int& out_h);

// Area-averaging resize (each output pixel the mean of the input area it covers, fractional pixels weighted).
Pixels resize_area(const Pixels& src, int width, int height);

// JPEG at `quality` (stb_image_write); `exif` (an APP1 payload "Exif\0\0" + TIFF, may be empty) is inserted
// after the SOI / JFIF header.
std::vector<uint8_t> encode_jpeg(const Pixels& px, int quality, const std::vector<uint8_t>& exif = {});
std::vector<uint8_t> encode_png_rgb(const Pixels& px);

}  // namespace hgs::prepare
