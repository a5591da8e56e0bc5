// COCO RLE: hand-made cases worked out from maskApi.c's definition, brute-force round trips, bad input.
#include <gtest/gtest.h>

#include <random>

#include "core/error.h"
#include "masks/rle.h"

using namespace hgs;
using namespace hgs::masks;

namespace {

// Reference: column-major runs straight from the definition.
std::vector<uint32_t> brute_counts(const std::vector<uint8_t>& m, int w, int h) {
  std::vector<uint8_t> seq;
  for (int x = 0; x < w; ++x)
    for (int y = 0; y < h; ++y) seq.push_back(m[size_t(y) * w + x]);
  std::vector<uint32_t> c;
  uint8_t cur = 0;
  uint32_t run = 0;
  for (uint8_t v : seq) {
    if (v != cur) c.push_back(run), run = 0, cur = v;
    ++run;
  }
  c.push_back(run);
  return c;
}

}  // namespace

TEST(Rle, HandMadeMaskColumnMajorStartingWithZeros) {
  // h = 3, w = 2; rows: [0 1], [1 1], [0 0] -> column-major 0 1 0 | 1 1 0 -> runs 1,1,1,2,1
  std::vector<uint8_t> m = {0, 1, 1, 1, 0, 0};
  Rle r = rle_encode(m, 2, 3);
  EXPECT_EQ(r.counts, (std::vector<uint32_t>{1, 1, 1, 2, 1}));
  // counts 0..2 as they are, then 2 - 1 = 1 and 1 - 1 = 0: "1" "1" "1" "1" "0"
  EXPECT_EQ(rle_counts_to_string(r.counts), "11110");
  EXPECT_EQ(rle_decode(r, "t"), m);
  // A mask starting with 1 has an empty first run of zeros.
  Rle full = rle_encode(std::vector<uint8_t>(6, 1), 2, 3);
  EXPECT_EQ(full.counts, (std::vector<uint32_t>{0, 6}));
}

TEST(Rle, HandMadeStringsNegativeDeltaAndMultiGroup) {
  // 5, 3, 10 as they are ('5', '3', ':'); 1 - 3 = -2 -> 5-bit group 11110 with the sign bit -> 30 + 48 = 'N'.
  EXPECT_EQ(rle_counts_to_string({5, 3, 10, 1}), "53:N");
  EXPECT_EQ(rle_counts_from_string("53:N", "t"), (std::vector<uint32_t>{5, 3, 10, 1}));
  // 100 = 3 * 32 + 4: first group 4 with the continuation bit (36 + 48 = 'T'), then 3 ('3').
  EXPECT_EQ(rle_counts_to_string({100}), "T3");
  EXPECT_EQ(rle_counts_from_string("T3", "t"), (std::vector<uint32_t>{100}));
  // 16 needs two groups although it fits in 5 bits: bit 4 of a last group is the sign.
  // (group 16 | continuation 32 = 48 -> '`', then 0 -> '0').
  EXPECT_EQ(rle_counts_to_string({16}), "`0");
  EXPECT_EQ(rle_counts_from_string("`0", "t"), (std::vector<uint32_t>{16}));
}

TEST(Rle, BruteForceRoundTrips) {
  std::mt19937 rng(3);
  for (int trial = 0; trial < 500; ++trial) {
    const int w = 1 + rng() % 13, h = 1 + rng() % 11;
    const double p = (rng() % 100) / 100.0;
    std::vector<uint8_t> m(size_t(w) * h);
    for (auto& v : m) v = (rng() % 1000) < p * 1000;
    Rle r = rle_encode(m, w, h);
    ASSERT_EQ(r.counts, brute_counts(m, w, h));
    const std::string s = rle_counts_to_string(r.counts);
    ASSERT_EQ(rle_counts_from_string(s, "t"), r.counts) << s;
    ASSERT_EQ(rle_decode(r, "t"), m);
  }
  // Large counts and deltas of both signs.
  std::vector<uint32_t> c;
  for (int i = 0; i < 200; ++i) c.push_back(uint32_t(rng() % (i % 3 ? 70000 : 40)));
  EXPECT_EQ(rle_counts_from_string(rle_counts_to_string(c), "t"), c);
}

TEST(Rle, BadInput) {
  Rle r;
  r.height = 2, r.width = 2;
  r.counts = {1, 2, 3};  // 6 > 4 pixels
  try {
    rle_decode(r, "x.json: mask 0");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("x.json: mask 0: RLE counts overrun"), std::string::npos) << e.what();
  }
  r.counts = {1, 2};  // 3 < 4 pixels
  EXPECT_THROW(rle_decode(r, "x"), Error);
  EXPECT_THROW(rle_counts_from_string("1 2", "x"), Error);  // ' ' is below '0'
  EXPECT_THROW(rle_counts_from_string("T", "x"), Error);    // continuation bit on the last character
  EXPECT_THROW(rle_counts_from_string("1N", "x"), Error);   // -2 as a first count
}
