// Inputs found by fuzzing core's loaders (fuzz/fuzz_npy.cpp, fuzz/fuzz_image.cpp; docs/reliability.md), each
// failing before its fix: they now give a one-line hgs::Error naming the file, or load correctly.
#include <gtest/gtest.h>

#include <string>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "core/npy.h"
#include "expect_error.h"
#include "test_util.h"

using namespace hgs;

namespace {
// A version 1.0 .npy file with this header dict and body.
std::string npy_bytes(const std::string& dict, const std::string& body) {
  std::string h = dict;
  while ((10 + h.size() + 1) % 64) h += ' ';
  h += '\n';
  std::string out = "\x93NUMPY\x01";
  out += '\0';
  out += char(h.size() & 255);
  out += char(h.size() >> 8);
  return out + h + body;
}
}  // namespace

// fuzz_npy: a 30-digit dimension threw std::out_of_range from std::stoull.
TEST(FuzzRegressions, NpyDimensionTooLargeForSizeT) {
  test::TempDir tmp;
  const auto f = tmp / "big.npy";
  atomic_write_text(f, npy_bytes("{'descr': '|u1', 'fortran_order': False, 'shape': (300000000000000000000000000000, 4), }", "x"));
  EXPECT_FILE_ERROR(read_npy(f), f, "too large");
  EXPECT_FILE_ERROR(read_npy_header(f), f, "too large");
}

// The element count overflowing size_t wrapped to 0: the array "loaded" with a shape promising 2^65 elements.
TEST(FuzzRegressions, NpyShapeProductOverflows) {
  test::TempDir tmp;
  const auto f = tmp / "wrap.npy";
  atomic_write_text(f, npy_bytes("{'descr': '<f4', 'fortran_order': False, 'shape': (4294967296, 4294967296, 2), }", ""));
  EXPECT_FILE_ERROR(read_npy(f), f, "too large");
}

// fuzz_npy under UBSan: an empty float32 array memcpy'd from a null pointer in to_float.
TEST(FuzzRegressions, NpyEmptyArrayToFloat) {
  test::TempDir tmp;
  const auto f = tmp / "empty.npy";
  atomic_write_text(f, npy_bytes("{'descr': '<f4', 'fortran_order': False, 'shape': (0, 7), }", ""));
  const NpyArray a = read_npy(f);
  EXPECT_EQ(a.size(), 0u);
  EXPECT_TRUE(a.to_float().empty());
}

// A header longer than any numpy writes is refused before the regex scans it.
TEST(FuzzRegressions, NpyHeaderTooLong) {
  test::TempDir tmp;
  const auto f = tmp / "long.npy";
  std::string b = "\x93NUMPY\x02";
  b += '\0';
  const uint32_t n = 1u << 20;
  b.append(reinterpret_cast<const char*>(&n), 4);
  b += std::string(n, ' ');
  atomic_write_text(f, b);
  EXPECT_FILE_ERROR(read_npy(f), f, "too long");
}

// fuzz_image: a 31-byte PNG whose header claims 220 x 4802568 16-bit grey pixels (2 GB) was allocated before
// decoding (out of memory); header sizes are now checked first.
TEST(FuzzRegressions, PngHeaderClaimsTooManyPixels) {
  test::TempDir t;
  const unsigned char png[] = {0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00, 0x0d, 0x49, 0x48, 0x44, 0x52,
                               0x00, 0x00, 0x00, 0xdc, 0x00, 0x49, 0x48, 0x08, 0x10, 0x00, 0x00, 0x00, 0x00, 0x11, 0x3b};
  const auto f = t / "mask.png";
  atomic_write_bytes(f, png, sizeof(png));
  EXPECT_FILE_ERROR(load_label_png(f), f, "too large");
  EXPECT_FILE_ERROR(load_image(f, 3), f, "too large");
}
