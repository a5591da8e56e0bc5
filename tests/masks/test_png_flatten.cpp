// Label PNG decoding (palette index, grey 8/16-bit, every scanline filter against a brute-force reference) and
// the overlap rule on a hand-made case.
#include <gtest/gtest.h>
#include <zlib.h>

#include <random>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "masks/flatten.h"
#include "masks/png_index.h"
#include "test_util.h"

using namespace hgs;
using namespace hgs::masks;

namespace {

void put32(std::vector<uint8_t>& o, uint32_t v) {
  for (int s = 24; s >= 0; s -= 8) o.push_back(uint8_t(v >> s));
}
void chunk(std::vector<uint8_t>& o, const char* t, const std::vector<uint8_t>& d) {
  put32(o, uint32_t(d.size()));
  size_t st = o.size();
  o.insert(o.end(), t, t + 4);
  o.insert(o.end(), d.begin(), d.end());
  put32(o, uint32_t(crc32(0, o.data() + st, uInt(d.size() + 4))));
}

// A grey or palette PNG of bit depth 1, 2 or 4: samples packed most significant first, rows padded to a byte.
std::vector<uint8_t> packed_png(const std::vector<uint8_t>& px, int w, int h, int ctype, int depth) {
  std::vector<uint8_t> raw;
  const int per = 8 / depth;
  for (int y = 0; y < h; ++y) {
    raw.push_back(0);
    for (int x0 = 0; x0 < w; x0 += per) {
      uint8_t b = 0;
      for (int k = 0; k < per; ++k)
        if (x0 + k < w) b |= uint8_t(px[size_t(y) * w + x0 + k] << (8 - depth * (k + 1)));
      raw.push_back(b);
    }
  }
  uLongf zl = compressBound(uLong(raw.size()));
  std::vector<uint8_t> z(zl);
  compress2(z.data(), &zl, raw.data(), uLong(raw.size()), 9);
  z.resize(zl);
  std::vector<uint8_t> o = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'}, ihdr;
  put32(ihdr, w);
  put32(ihdr, h);
  ihdr.insert(ihdr.end(), {uint8_t(depth), uint8_t(ctype), 0, 0, 0});
  chunk(o, "IHDR", ihdr);
  if (ctype == 3) chunk(o, "PLTE", std::vector<uint8_t>(3 << depth, 200));
  chunk(o, "IDAT", z);
  chunk(o, "IEND", {});
  return o;
}

// An 8-bit grey or palette PNG whose row y is filtered with filter y % 5 (filters applied from their definition).
std::vector<uint8_t> filtered_png(const std::vector<uint8_t>& px, int w, int h, int ctype) {
  std::vector<uint8_t> raw;
  std::vector<int> prev(w, 0);
  for (int y = 0; y < h; ++y) {
    const int f = y % 5;
    raw.push_back(uint8_t(f));
    for (int x = 0; x < w; ++x) {
      const int cur = px[size_t(y) * w + x], a = x ? px[size_t(y) * w + x - 1] : 0, b = prev[x],
                c = x ? prev[x - 1] : 0;
      int pred = 0;
      if (f == 1) pred = a;
      if (f == 2) pred = b;
      if (f == 3) pred = (a + b) / 2;
      if (f == 4) {
        int p = a + b - c, pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
        pred = (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
      }
      raw.push_back(uint8_t(cur - pred));
    }
    for (int x = 0; x < w; ++x) prev[x] = px[size_t(y) * w + x];
  }
  uLongf zl = compressBound(uLong(raw.size()));
  std::vector<uint8_t> z(zl);
  compress2(z.data(), &zl, raw.data(), uLong(raw.size()), 9);
  z.resize(zl);
  std::vector<uint8_t> o = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'}, ihdr;
  put32(ihdr, w);
  put32(ihdr, h);
  ihdr.insert(ihdr.end(), {8, uint8_t(ctype), 0, 0, 0});
  chunk(o, "IHDR", ihdr);
  if (ctype == 3) chunk(o, "PLTE", std::vector<uint8_t>(768, 7));
  chunk(o, "IDAT", z);
  chunk(o, "IEND", {});
  return o;
}

}  // namespace

TEST(IndexPng, PaletteGivesTheIndexNotTheColour) {
  LabelMap m(5, 3);
  for (size_t i = 0; i < m.v.size(); ++i) m.v[i] = uint16_t((i * 7) % 6);
  // Every entry the same colour: a decoder that expands the palette would see one label.
  std::vector<uint8_t> pal(6 * 3, 128);
  auto png = encode_palette_png(m, pal);
  LabelMap d = decode_index_png(png.data(), png.size(), "p.png");
  EXPECT_EQ(d.width, 5);
  EXPECT_EQ(d.height, 3);
  EXPECT_EQ(d.v, m.v);
}

TEST(IndexPng, GreyEightAndSixteenBitAgreeWithTheSceneLoader) {
  test::TempDir t;
  LabelMap m(7, 4);
  for (size_t i = 0; i < m.v.size(); ++i) m.v[i] = uint16_t(i * 3);
  save_label_png(t / "a.png", m);
  EXPECT_EQ(load_index_png(t / "a.png").v, m.v);
  m.v[3] = 40000;  // forces 16 bits
  save_label_png(t / "b.png", m);
  EXPECT_EQ(load_index_png(t / "b.png").v, m.v);
  EXPECT_EQ(load_label_png(t / "b.png").v, m.v);
}

TEST(IndexPng, EveryScanlineFilterMatchesTheReference) {
  std::mt19937 rng(5);
  const int w = 9, h = 11;
  std::vector<uint8_t> px(size_t(w) * h);
  for (auto& v : px) v = uint8_t(rng() % 256);
  for (int ctype : {0, 3}) {
    auto png = filtered_png(px, w, h, ctype);
    LabelMap d = decode_index_png(png.data(), png.size(), "f.png");
    for (size_t i = 0; i < px.size(); ++i) ASSERT_EQ(d.v[i], px[i]) << "pixel " << i << " colour type " << ctype;
  }
}

TEST(IndexPng, SubByteDepths) {
  std::mt19937 rng(9);
  const int w = 11, h = 5;  // 11 is not a multiple of 8 / depth: rows end in a padded byte
  for (int ctype : {0, 3})
    for (int depth : {1, 2, 4}) {
      std::vector<uint8_t> px(size_t(w) * h);
      for (auto& v : px) v = uint8_t(rng() % (1 << depth));
      auto png = packed_png(px, w, h, ctype, depth);
      LabelMap d = decode_index_png(png.data(), png.size(), "d.png");
      for (size_t i = 0; i < px.size(); ++i)
        ASSERT_EQ(d.v[i], px[i]) << "depth " << depth << " type " << ctype << " pixel " << i;
    }
}

TEST(IndexPng, BadInput) {
  LabelMap m(3, 2, 1);
  auto nopal = encode_palette_png(m, {});
  try {
    decode_index_png(nopal.data(), nopal.size(), "frame.png");
    FAIL();
  } catch (const Error& e) {
    EXPECT_EQ(std::string(e.what()), "frame.png: palette PNG without a palette (no PLTE chunk)");
  }
  Image rgb(3, 2, 3, 0.5f);
  auto png = encode_png(3, 2, 3, 8, std::vector<uint8_t>(18, 9).data());
  EXPECT_THROW(decode_index_png(png.data(), png.size(), "rgb.png"), Error);
  auto good = encode_palette_png(m, {1, 2, 3});
  good.resize(good.size() - 20);  // truncated
  EXPECT_THROW(decode_index_png(good.data(), good.size(), "cut.png"), Error);
}

TEST(Flatten, SmallestMaskWinsTiesGoToTheFirstListed) {
  // 4 x 3 image. Mask 0: whole object, columns 0-2 of every row (9 px). Mask 1: its part, column 0 (3 px).
  // Mask 2: a 3-px strip (row 0, columns 1-3) that overlaps mask 0 and ties with mask 1 in area.
  // Mask 3: the same pixels as mask 2 (a duplicate listed later): loses every tie to mask 2.
  const int W = 4, H = 3;
  auto make = [&](std::initializer_list<std::pair<int, int>> px, double iou, double stab) {
    std::vector<uint8_t> b(W * H, 0);
    for (auto [x, y] : px) b[y * W + x] = 1;
    SourceMask s;
    s.rle = rle_encode(b, W, H);
    s.predicted_iou = iou;
    s.stability_score = stab;
    return s;
  };
  std::vector<SourceMask> ms = {make({{0, 0}, {1, 0}, {2, 0}, {0, 1}, {1, 1}, {2, 1}, {0, 2}, {1, 2}, {2, 2}}, 0.9,
                                     0.8),
                                make({{0, 0}, {0, 1}, {0, 2}}, 1.2, 0.5),  // iou above 1 is clamped
                                make({{1, 0}, {2, 0}, {3, 0}}, 0.7, -1),   // no stability: iou alone
                                make({{1, 0}, {2, 0}, {3, 0}}, 0.1, 0.1)};
  Flattened f = flatten_masks(ms, W, H);
  const std::vector<uint16_t> want = {2, 3, 3, 3, 2, 1, 1, 0, 2, 1, 1, 0};
  EXPECT_EQ(f.labels.v, want);
  EXPECT_EQ(f.visible, (std::vector<uint64_t>{4, 3, 3, 0}));
  ASSERT_EQ(f.confidence.size(), 12u);
  EXPECT_FLOAT_EQ(f.confidence[0], 0.5f);  // mask 1: clamp(1.2) * 0.5
  EXPECT_FLOAT_EQ(f.confidence[1], 0.7f);  // mask 2
  EXPECT_FLOAT_EQ(f.confidence[5], float(0.9 * 0.8));
  EXPECT_FLOAT_EQ(f.confidence[7], 1.f);  // no mask
  // Mask 1 lies inside mask 0; mask 2 has 2 of its 3 pixels in mask 0 (below 90%); mask 3 equals mask 2 in
  // area, and a part must be strictly smaller than its whole.
  EXPECT_EQ(part_of(ms), (std::vector<int>{-1, 0, -1, -1}));
  EXPECT_EQ(part_of(ms, 0.6), (std::vector<int>{-1, 0, 0, 0}));
  // Without scores there is no confidence map.
  for (auto& m : ms) m.predicted_iou = m.stability_score = -1;
  EXPECT_TRUE(flatten_masks(ms, W, H).confidence.empty());
}

TEST(Flatten, PartOfMatchesABruteForceCount) {
  std::mt19937 rng(11);
  const int W = 9, H = 7;
  int parts = 0;
  for (int trial = 0; trial < 100; ++trial) {
    std::vector<SourceMask> ms(2 + rng() % 6);
    std::vector<std::vector<uint8_t>> bits;
    for (auto& m : ms) {
      std::vector<uint8_t> b(W * H, 0);
      const int x0 = rng() % W, y0 = rng() % H, x1 = x0 + rng() % (W - x0), y1 = y0 + rng() % (H - y0);
      for (int y = y0; y <= y1; ++y)
        for (int x = x0; x <= x1; ++x) b[y * W + x] = trial % 2 || rng() % 5 != 0;  // odd trials: solid boxes
      m.rle = rle_encode(b, W, H);
      bits.push_back(b);
    }
    std::vector<int> want(ms.size(), -1);
    for (size_t i = 0; i < ms.size(); ++i) {
      const uint64_t ai = rle_area(ms[i].rle);
      for (size_t j = 0; j < ms.size(); ++j) {
        const uint64_t aj = rle_area(ms[j].rle);
        uint64_t n = 0;
        for (int p = 0; p < W * H; ++p) n += bits[i][p] && bits[j][p];
        if (j == i || ai == 0 || aj <= ai || double(n) < 0.9 * double(ai)) continue;  // an empty mask is nobody's part
        if (want[i] < 0 || aj < rle_area(ms[want[i]].rle)) want[i] = int(j);
      }
    }
    ASSERT_EQ(part_of(ms), want) << "trial " << trial;
    for (int p : want) parts += p >= 0;
  }
  EXPECT_GT(parts, 30);  // the cases do exercise the relation
}
