#include <gtest/gtest.h>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "test_util.h"

using namespace hgs;

TEST(Image, PngRoundTrip8Bit) {
  test::TempDir tmp;
  Image a(13, 7, 3);
  for (size_t i = 0; i < a.px.size(); ++i) a.px[i] = float(i % 256) / 255.f;
  save_png(tmp / "a.png", a);
  Image b = load_image(tmp / "a.png", 3);
  ASSERT_EQ(b.width, 13);
  ASSERT_EQ(b.height, 7);
  for (size_t i = 0; i < a.px.size(); ++i) EXPECT_NEAR(a.px[i], b.px[i], 1e-6);
  int w, h;
  image_size(tmp / "a.png", w, h);
  EXPECT_EQ(w, 13);
  EXPECT_EQ(h, 7);
}

TEST(Image, LabelPng8And16Bit) {
  test::TempDir tmp;
  for (uint16_t top : {200, 1000}) {
    LabelMap m(9, 5);
    for (size_t i = 0; i < m.v.size(); ++i) m.v[i] = static_cast<uint16_t>((i * 7) % (top + 1));
    m.v[3] = top;
    save_label_png(tmp / "m.png", m);
    LabelMap r = load_label_png(tmp / "m.png");
    EXPECT_EQ(r.width, 9);
    EXPECT_EQ(r.v, m.v);
  }
}

TEST(Image, ColourPngIsNotALabelMap) {
  test::TempDir tmp;
  save_png(tmp / "c.png", Image(4, 4, 3, 0.5f));
  EXPECT_THROW(load_label_png(tmp / "c.png"), Error);
}

TEST(Image, CorruptPngGivesOneLineError) {
  test::TempDir tmp;
  Image a(8, 8, 3, 0.2f);
  save_png(tmp / "a.png", a);
  auto bytes = read_file_bytes(tmp / "a.png");
  bytes.resize(bytes.size() / 2);
  atomic_write_bytes(tmp / "b.png", bytes.data(), bytes.size());
  try {
    load_image(tmp / "b.png");
    FAIL();
  } catch (const Error& e) {
    std::string m = e.what();
    EXPECT_NE(m.find("b.png: cannot decode image"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos);
  }
}

TEST(Image, AreaDownscaleAveragesBlocks) {
  Image a(5, 4, 1);
  for (int y = 0; y < 4; ++y)
    for (int x = 0; x < 5; ++x) a.at(x, y) = float(x + 10 * y);
  Image b = downscale_area(a, 2);
  ASSERT_EQ(b.width, 2);
  ASSERT_EQ(b.height, 2);
  EXPECT_FLOAT_EQ(b.at(0, 0), (0 + 1 + 10 + 11) / 4.f);
  EXPECT_FLOAT_EQ(b.at(1, 1), (22 + 23 + 32 + 33) / 4.f);
}

TEST(Fs, AtomicWriteLeavesNothingOnFailure) {
  test::TempDir tmp;
  EXPECT_THROW(atomic_write(tmp / "x.bin",
                            [](const std::filesystem::path& p) {
                              atomic_write_text(p, "partial");
                              throw Error("boom");
                            }),
               Error);
  EXPECT_TRUE(std::filesystem::is_empty(tmp.path));
}
