// COCO run-length encoding of binary masks, as pycocotools' maskApi.c defines it (our own implementation):
// a mask of size h x w is read in column-major order (x outer, y inner) and stored as alternating run lengths,
// starting with a run of 0s (which may be empty). The compressed string form encodes each count (from the
// fourth on, as the difference to the count two places earlier) in 5-bit groups, least significant first,
// one character per group: bit 5 = more groups follow, bit 4 of the last group = sign, character = value + 48.
#pragma once
#include <cstdint>
#include <string>
#include <vector>

namespace hgs::masks {

struct Rle {
  int height = 0, width = 0;
  std::vector<uint32_t> counts;  // alternating runs of 0s and 1s, column-major
};

// Decodes the compressed string form into counts. `where` names the file for errors (bad character, a
// truncated group, a negative count).
std::vector<uint32_t> rle_counts_from_string(const std::string& s, const std::string& where);
std::string rle_counts_to_string(const std::vector<uint32_t>& counts);

// Binary mask [H, W] row-major (1 = inside) -> RLE.
Rle rle_encode(const std::vector<uint8_t>& mask, int width, int height);
// Fails (naming `where`) unless the counts cover exactly h x w pixels: "overrun" when they run past the end.
void rle_check(const Rle& rle, const std::string& where);
// RLE -> binary mask [H, W] row-major. Fails (naming `where`) unless the counts cover exactly h x w pixels.
std::vector<uint8_t> rle_decode(const Rle& rle, const std::string& where);

}  // namespace hgs::masks
