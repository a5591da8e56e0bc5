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
  atomic_write_text(
      f, npy_bytes("{'descr': '|u1', 'fortran_order': False, 'shape': (300000000000000000000000000000, 4), }", "x"));
  EXPECT_FILE_ERROR(read_npy(f), f, "too large");
  EXPECT_FILE_ERROR(read_npy_header(f), f, "too large");
}

// The element count overflowing size_t wrapped to 0: the array "loaded" with a shape promising 2^65 elements.
TEST(FuzzRegressions, NpyShapeProductOverflows) {
  test::TempDir tmp;
  const auto f = tmp / "wrap.npy";
  atomic_write_text(f,
                    npy_bytes("{'descr': '<f4', 'fortran_order': False, 'shape': (4294967296, 4294967296, 2), }", ""));
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
  const unsigned char png[] = {0x89, 0x50, 0x4e, 0x47, 0x0d, 0x0a, 0x1a, 0x0a, 0x00, 0x00, 0x00,
                               0x0d, 0x49, 0x48, 0x44, 0x52, 0x00, 0x00, 0x00, 0xdc, 0x00, 0x49,
                               0x48, 0x08, 0x10, 0x00, 0x00, 0x00, 0x00, 0x11, 0x3b};
  const auto f = t / "mask.png";
  atomic_write_bytes(f, png, sizeof(png));
  EXPECT_FILE_ERROR(load_label_png(f), f, "too large");
  EXPECT_FILE_ERROR(load_image(f, 3), f, "too large");
}

// fuzz_image (out of memory): a 239-byte PNG (two IHDR, then an IDAT claiming 2032624932 bytes) made
// stb_image allocate 2 GB for that chunk before reading it; chunk lengths are now checked against the file.
TEST(FuzzRegressions, PngChunkLongerThanTheFile) {
  test::TempDir t;
  const std::string hex =
      "89504e470d0a1a0a0000000d494844520000000c000000081002000000121655e5000000594944415478da6360606060"
      "6460627ec1fc92f915fb05f68bec97b87770efe4dec5bf807f21ff22e10ee14ee12ef102f142f122e989504e470d0a1a"
      "0a0000000d494844520000000c00000008080400000067edd67a00000008e948e92879077947792765244944415478da"
      "636060e4e40d654d652d750175417521ad1f5a3fb57e308c1a34920d0200492da441356257b20000000049454e44ae42"
      "6012129696518251d5d53333b777f0f00c0c8a8a4e4e61185a1200068a2581c02461b90000000049454e44ae426082";
  std::string bytes;
  for (size_t i = 0; i + 1 < hex.size(); i += 2) bytes += char(std::stoi(hex.substr(i, 2), nullptr, 16));
  ASSERT_EQ(bytes.size(), 239u);
  const auto f = t / "chunk.png";
  atomic_write_bytes(f, bytes.data(), bytes.size());
  EXPECT_FILE_ERROR(load_image(f, 3), f, "claims 2032624932 bytes");
  EXPECT_FILE_ERROR(load_label_png(f), f, "PNG chunk");
}
