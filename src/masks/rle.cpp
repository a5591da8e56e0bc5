// COCO RLE: column-major runs starting with 0s; compressed string form as in pycocotools (see rle.h).
#include "masks/rle.h"

#include "core/error.h"

namespace hgs::masks {

std::vector<uint32_t> rle_counts_from_string(const std::string& s, const std::string& where) {
  std::vector<int64_t> c;
  size_t p = 0;
  while (p < s.size()) {
    int64_t x = 0;
    int k = 0;
    bool more = true;
    while (more) {
      if (p >= s.size()) fail("{}: RLE counts string ends inside a number", where);
      const int ch = static_cast<unsigned char>(s[p]) - 48;
      if (ch < 0 || ch > 63) fail("{}: RLE counts string has an invalid character '{}'", where, s[p]);
      if (k > 12) fail("{}: RLE counts string has a number too long", where);
      x |= int64_t(ch & 0x1f) << (5 * k);
      more = ch & 0x20;
      ++p;
      ++k;
      if (!more && (ch & 0x10)) x |= -(int64_t(1) << (5 * k));  // sign of the last group
    }
    if (c.size() > 2) x += c[c.size() - 2];
    if (x < 0 || x > int64_t(UINT32_MAX))
      fail("{}: RLE count {} at position {} is negative or too large", where, x, c.size());
    c.push_back(x);
  }
  return std::vector<uint32_t>(c.begin(), c.end());
}

std::string rle_counts_to_string(const std::vector<uint32_t>& counts) {
  std::string s;
  for (size_t i = 0; i < counts.size(); ++i) {
    int64_t x = counts[i];
    if (i > 2) x -= counts[i - 2];
    bool more = true;
    while (more) {
      int ch = static_cast<int>(x & 0x1f);
      x >>= 5;  // arithmetic shift: negative values stay negative
      more = (ch & 0x10) ? x != -1 : x != 0;
      if (more) ch |= 0x20;
      s.push_back(static_cast<char>(ch + 48));
    }
  }
  return s;
}

Rle rle_encode(const std::vector<uint8_t>& mask, int width, int height) {
  Rle r;
  r.width = width;
  r.height = height;
  uint8_t prev = 0;
  uint32_t run = 0;
  for (int x = 0; x < width; ++x)
    for (int y = 0; y < height; ++y) {
      const uint8_t v = mask[size_t(y) * width + x] ? 1 : 0;
      if (v != prev) {
        r.counts.push_back(run);
        run = 0;
        prev = v;
      }
      ++run;
    }
  r.counts.push_back(run);
  return r;
}

void rle_check(const Rle& r, const std::string& where) {
  const uint64_t n = uint64_t(r.width) * r.height;
  uint64_t pos = 0;
  for (size_t i = 0; i < r.counts.size(); ++i) {
    if (pos + r.counts[i] > n)
      fail("{}: RLE counts overrun the mask: run {} ends at pixel {} but size is {}x{} = {} pixels", where, i,
           pos + r.counts[i], r.height, r.width, n);
    pos += r.counts[i];
  }
  if (pos != n) fail("{}: RLE counts cover {} pixels but size is {}x{} = {} pixels", where, pos, r.height, r.width, n);
}

std::vector<uint8_t> rle_decode(const Rle& r, const std::string& where) {
  rle_check(r, where);
  const uint64_t n = uint64_t(r.width) * r.height;
  std::vector<uint8_t> m(n, 0);
  uint64_t pos = 0;
  uint8_t v = 0;
  for (size_t i = 0; i < r.counts.size(); ++i, v ^= 1) {
    if (v)
      for (uint64_t p = pos; p < pos + r.counts[i]; ++p) {
        const uint64_t x = p / r.height, y = p % r.height;  // column-major
        m[y * r.width + x] = 1;
      }
    pos += r.counts[i];
  }
  return m;
}

}  // namespace hgs::masks
