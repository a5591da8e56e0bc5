// Label PNGs read as stored: palette (indexed-colour) PNGs give the palette INDEX of each pixel, not its colour
// (stb_image and other generic decoders expand the palette to RGB, which loses the label), and greyscale PNGs
// give their sample value (1, 2, 4, 8 or 16 bits). Our own small decoder on zlib: chunks (CRC checked), IHDR,
// PLTE, IDAT inflated, the five scanline filters undone; non-interlaced images only.
#pragma once
#include <cstdint>
#include <filesystem>
#include <vector>

#include "core/image.h"

namespace hgs::masks {

// Fails with a one-line error naming the file for: a colour (RGB/RGBA) or grey+alpha PNG, a palette PNG without
// a PLTE chunk, an interlaced PNG, a corrupt or truncated file.
LabelMap load_index_png(const std::filesystem::path& path);
// Parses PNG bytes; `name` is used in errors.
LabelMap decode_index_png(const uint8_t* bytes, size_t size, const std::string& name);

// Writes a palette PNG (colour type 3, 8-bit) whose pixels are `labels` (all <= 255) with the given palette of
// [n, 3] RGB entries (n <= 256; an empty palette omits PLTE, which makes an invalid file, for tests). Returns the
// bytes.
std::vector<uint8_t> encode_palette_png(const LabelMap& labels, const std::vector<uint8_t>& palette_rgb);

}  // namespace hgs::masks
