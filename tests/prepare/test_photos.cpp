// The input stage on photo folders (prepare/photos.h): EXIF orientations 1-8 against the EXIF table, area
// downscaling against a brute-force area integral, byte copies, files that are not images, truncated and
// undecodable files (error or skip), resume, and name collisions. Test images are written here with stb.
#include <gtest/gtest.h>
#include <libexif/exif-data.h>
#include <stb/stb_image.h>

#include <array>
#include <cmath>
#include <cstdlib>
#include <fstream>
#include <set>

#include "core/error.h"
#include "core/fs.h"
#include "core/json_file.h"
#include "expect_error.h"
#include "prepare/exif.h"
#include "prepare/photos.h"
#include "prepare/pixels.h"
#include "test_util.h"

namespace hgs::prepare {
namespace {
namespace fs = std::filesystem;
using test::TempDir;

using RGB = std::array<int, 3>;
// Quadrant colours of the pattern image: 0 top-left, 1 top-right, 2 bottom-left, 3 bottom-right.
const RGB kQuad[4] = {{220, 30, 30}, {30, 220, 30}, {30, 30, 220}, {220, 220, 30}};

Pixels quadrants(int w, int h) {
  Pixels p;
  p.width = w;
  p.height = h;
  p.v.resize(size_t(w) * h * 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) p.v[(size_t(y) * w + x) * 3 + c] = uint8_t(kQuad[(y >= h / 2) * 2 + (x >= w / 2)][c]);
  return p;
}

// An APP1 segment with one IFD0 entry, Orientation (0x0112, SHORT), in big- ("MM") or little-endian ("II") TIFF.
std::vector<uint8_t> exif_app1(int orientation, bool big_endian) {
  std::vector<uint8_t> t = {'E', 'x', 'i', 'f', 0, 0};
  auto put = [&](uint32_t v, int bytes) {
    for (int i = 0; i < bytes; ++i) t.push_back(uint8_t(v >> 8 * (big_endian ? bytes - 1 - i : i)));
  };
  t.push_back(big_endian ? 'M' : 'I');
  t.push_back(big_endian ? 'M' : 'I');
  put(42, 2);
  put(8, 4);  // IFD0 right after the header
  put(1, 2);  // one entry: tag, type SHORT, count 1, value left-justified in 4 bytes
  put(0x0112, 2), put(3, 2), put(1, 4), put(uint32_t(orientation), 2), put(0, 2);
  put(0, 4);  // no next IFD
  const size_t len = t.size() + 2;
  std::vector<uint8_t> seg(len + 2);  // (built in place: GCC 12 warns falsely on inserting into a short vector)
  seg[0] = 0xFF, seg[1] = 0xE1, seg[2] = uint8_t(len >> 8), seg[3] = uint8_t(len);
  std::copy(t.begin(), t.end(), seg.begin() + 4);
  return seg;
}

// A JPEG of `p`, with an EXIF orientation right after SOI (as cameras write it) when orientation > 0.
std::vector<uint8_t> jpeg_bytes(const Pixels& p, int orientation = 0) {
  std::vector<uint8_t> b = encode_jpeg(p, 95);
  if (orientation > 0) {
    const auto seg = exif_app1(orientation, orientation % 2 == 1);
    b.insert(b.begin() + 2, seg.begin(), seg.end());
  }
  return b;
}

void write(const fs::path& p, const std::vector<uint8_t>& b) { atomic_write_bytes(p, b.data(), b.size()); }

Pixels read_rgb(const fs::path& p) {
  int w, h, c;
  uint8_t* d = stbi_load(p.c_str(), &w, &h, &c, 3);
  EXPECT_NE(d, nullptr) << p;
  Pixels out;
  if (!d) return out;
  out.width = w, out.height = h;
  out.v.assign(d, d + size_t(w) * h * 3);
  stbi_image_free(d);
  return out;
}

InputOptions quiet(int max_size = 0) {
  InputOptions o;
  o.max_size = max_size;
  o.progress = false;
  return o;
}

// Which stored quadrant each displayed corner shows (TL, TR, BL, BR), from the EXIF table: where row 0 / column 0
// of the stored image are displayed -- 1 top/left, 2 top/right, 3 bottom/right, 4 bottom/left, 5 left/top,
// 6 right/top, 7 right/bottom, 8 left/bottom.
const int kShown[9][4] = {{},           {0, 1, 2, 3}, {1, 0, 3, 2}, {3, 2, 1, 0}, {2, 3, 0, 1},
                          {0, 2, 1, 3}, {2, 0, 3, 1}, {3, 1, 2, 0}, {1, 3, 0, 2}};

TEST(Photos, EveryExifOrientationIsAppliedAsTheTableSays) {
  TempDir t;
  fs::create_directories(t / "in");
  for (int o = 1; o <= 8; ++o) write(t / "in" / fmt::format("o{}.jpg", o), jpeg_bytes(quadrants(48, 32), o));
  const InputReport r = import_photos(t / "in", t / "out", quiet());
  ASSERT_EQ(r.images.size(), 8u);
  for (int o = 1; o <= 8; ++o) {
    SCOPED_TRACE(fmt::format("orientation {}", o));
    const InputImage& im = r.images[o - 1];
    EXPECT_EQ(im.orientation, o);
    const Pixels p = read_rgb(t / "out" / im.name);
    ASSERT_EQ(p.width, o >= 5 ? 32 : 48);
    ASSERT_EQ(p.height, o >= 5 ? 48 : 32);
    EXPECT_EQ(im.width, p.width);
    EXPECT_EQ(im.height, p.height);
    for (int corner = 0; corner < 4; ++corner) {
      const int x = (corner % 2 ? 3 : 1) * p.width / 4, y = (corner / 2 ? 3 : 1) * p.height / 4;
      for (int c = 0; c < 3; ++c)
        EXPECT_NEAR(p.v[(size_t(y) * p.width + x) * 3 + c], kQuad[kShown[o][corner]][c], 40) << "corner " << corner;
    }
    const auto out = read_file_bytes(t / "out" / im.name);
    EXPECT_EQ(exif_orientation(out.data(), out.size()), 1) << "a rewritten photo must not be turned again";
    if (o > 1) {  // the EXIF is carried over (COLMAP reads the camera from it), its orientation reset to 1
      ExifData* ed = exif_data_new_from_data(out.data(), unsigned(out.size()));
      ExifEntry* e = ed ? exif_content_get_entry(ed->ifd[EXIF_IFD_0], EXIF_TAG_ORIENTATION) : nullptr;
      EXPECT_TRUE(e && exif_get_short(e->data, exif_data_get_byte_order(ed)) == 1);
      if (ed) exif_data_unref(ed);
    }
    if (o == 1) {
      EXPECT_EQ(out, read_file_bytes(t / "in" / im.name)) << "nothing to change: a byte copy";
    }
  }
}

TEST(Photos, ExifOrientationIsReadInBothByteOrders) {
  for (int o = 1; o <= 8; ++o)
    for (bool be : {false, true}) {
      std::vector<uint8_t> b = encode_jpeg(quadrants(8, 8), 90);
      const auto seg = exif_app1(o, be);
      b.insert(b.begin() + 2, seg.begin(), seg.end());
      EXPECT_EQ(exif_orientation(b.data(), b.size()), o) << (be ? "MM" : "II");
    }
  const auto plain = encode_jpeg(quadrants(8, 8), 90);
  EXPECT_EQ(exif_orientation(plain.data(), plain.size()), 1);
}

// Adds a one-component SHORT or LONG entry (libexif frees entry data with free()).
void add_number(ExifData* ed, ExifIfd ifd, ExifTag tag, ExifFormat format, uint32_t value) {
  ExifEntry* e = exif_entry_new();
  e->tag = tag;
  e->format = format;
  e->components = 1;
  e->size = format == EXIF_FORMAT_SHORT ? 2 : 4;
  e->data = static_cast<unsigned char*>(std::malloc(e->size));
  if (format == EXIF_FORMAT_SHORT) exif_set_short(e->data, exif_data_get_byte_order(ed), ExifShort(value));
  else exif_set_long(e->data, exif_data_get_byte_order(ed), value);
  exif_content_add_entry(ed->ifd[ifd], e);
  exif_entry_unref(e);
}

uint32_t number(ExifData* ed, ExifIfd ifd, ExifTag tag) {
  ExifEntry* e = exif_content_get_entry(ed->ifd[ifd], tag);
  if (!e) return 0;
  const ExifByteOrder o = exif_data_get_byte_order(ed);
  return e->format == EXIF_FORMAT_SHORT ? exif_get_short(e->data, o) : exif_get_long(e->data, o);
}

TEST(Photos, ARewrittenJpegKeepsItsExifUpright) {
  ExifData* ed = exif_data_new();
  add_number(ed, EXIF_IFD_0, EXIF_TAG_ORIENTATION, EXIF_FORMAT_SHORT, 6);
  add_number(ed, EXIF_IFD_EXIF, EXIF_TAG_FOCAL_LENGTH_IN_35MM_FILM, EXIF_FORMAT_SHORT, 28);
  add_number(ed, EXIF_IFD_EXIF, EXIF_TAG_PIXEL_X_DIMENSION, EXIF_FORMAT_LONG, 300);
  add_number(ed, EXIF_IFD_EXIF, EXIF_TAG_PIXEL_Y_DIMENSION, EXIF_FORMAT_LONG, 200);
  const auto thumb = encode_jpeg(quadrants(30, 20), 80);
  ed->data = static_cast<unsigned char*>(std::malloc(thumb.size()));
  std::copy(thumb.begin(), thumb.end(), ed->data);
  ed->size = unsigned(thumb.size());
  unsigned char* buf = nullptr;
  unsigned size = 0;
  exif_data_save_data(ed, &buf, &size);
  exif_data_unref(ed);
  ASSERT_NE(buf, nullptr);
  TempDir t;
  fs::create_directories(t / "in");
  write(t / "in" / "cam.jpg", encode_jpeg(quadrants(300, 200), 95, std::vector<uint8_t>(buf, buf + size)));
  std::free(buf);
  const InputReport r = import_photos(t / "in", t / "out", quiet(100));
  ASSERT_EQ(r.images.size(), 1u);
  EXPECT_EQ(r.images[0].orientation, 6);
  const auto out = read_file_bytes(t / "out" / "cam.jpg");
  ExifData* got = exif_data_new_from_data(out.data(), unsigned(out.size()));
  ASSERT_NE(got, nullptr);
  EXPECT_EQ(number(got, EXIF_IFD_0, EXIF_TAG_ORIENTATION), 1u);
  EXPECT_EQ(number(got, EXIF_IFD_EXIF, EXIF_TAG_FOCAL_LENGTH_IN_35MM_FILM), 28u);
  EXPECT_EQ(number(got, EXIF_IFD_EXIF, EXIF_TAG_PIXEL_X_DIMENSION), 67u);
  EXPECT_EQ(number(got, EXIF_IFD_EXIF, EXIF_TAG_PIXEL_Y_DIMENSION), 100u);
  EXPECT_EQ(got->size, 0u) << "the thumbnail (still turned) is dropped";
  exif_data_unref(got);
}

TEST(Photos, AreaResizeMatchesTheAreaIntegral) {
  Pixels src;
  src.width = 7, src.height = 5;
  for (int i = 0; i < 7 * 5 * 3; ++i) src.v.push_back(uint8_t((i * 37 + i * i) % 256));
  for (auto [w, h] : {std::pair{3, 2}, {4, 3}, {7, 5}, {2, 4}}) {
    const Pixels d = resize_area(src, w, h);
    ASSERT_EQ(d.width, w);
    ASSERT_EQ(d.height, h);
    const double sx = 7.0 / w, sy = 5.0 / h;
    auto overlap = [](double a0, double a1, double b0, double b1) {
      return std::max(0.0, std::min(a1, b1) - std::max(a0, b0));
    };
    for (int Y = 0; Y < h; ++Y)
      for (int X = 0; X < w; ++X)
        for (int c = 0; c < 3; ++c) {
          double acc = 0;  // brute force: every input pixel times its overlap with the output pixel's area
          for (int y = 0; y < 5; ++y)
            for (int x = 0; x < 7; ++x)
              acc += src.v[(y * 7 + x) * 3 + c] * overlap(X * sx, (X + 1) * sx, x, x + 1) *
                     overlap(Y * sy, (Y + 1) * sy, y, y + 1);
          EXPECT_NEAR(d.v[(Y * w + X) * 3 + c], acc / (sx * sy), 0.51) << w << "x" << h << " at " << X << "," << Y;
        }
  }
}

TEST(Photos, FitSizeBoundsTheLongestSideAndKeepsTheAspect) {
  int w, h;
  EXPECT_TRUE(fit_size(300, 200, 100, w, h));
  EXPECT_EQ(w, 100);
  EXPECT_EQ(h, 67);
  EXPECT_TRUE(fit_size(200, 300, 100, w, h));
  EXPECT_EQ(w, 67);
  EXPECT_EQ(h, 100);
  EXPECT_FALSE(fit_size(100, 50, 100, w, h));  // never enlarged
  EXPECT_EQ(w, 100);
  EXPECT_FALSE(fit_size(5000, 50, 0, w, h));  // 0 keeps the size
  EXPECT_TRUE(fit_size(4000, 1, 100, w, h));
  EXPECT_EQ(h, 1);
}

TEST(Photos, DownscalesJpegAndPngAndCopiesWhatNeedsNoChange) {
  TempDir t;
  fs::create_directories(t / "in");
  write(t / "in" / "big.png", encode_png_rgb(quadrants(300, 200)));
  write(t / "in" / "tall.jpg", jpeg_bytes(quadrants(300, 200), 6));  // upright it is 200 x 300
  write(t / "in" / "small.png", encode_png_rgb(quadrants(90, 60)));
  write(t / "in" / "small.jpg", jpeg_bytes(quadrants(90, 60)));
  const InputReport r = import_photos(t / "in", t / "out", quiet(100));
  ASSERT_EQ(r.images.size(), 4u);
  EXPECT_EQ(r.images[0].name, "big.png");
  int w, h, c;
  ASSERT_TRUE(stbi_info((t / "out" / "big.png").c_str(), &w, &h, &c));
  EXPECT_EQ(w, 100);
  EXPECT_EQ(h, 67);
  EXPECT_TRUE(r.images[0].resized);
  EXPECT_EQ(read_file_bytes(t / "out" / "big.png")[1], 'P') << "PNG input stays PNG";
  ASSERT_TRUE(stbi_info((t / "out" / "tall.jpg").c_str(), &w, &h, &c));
  EXPECT_EQ(w, 67);
  EXPECT_EQ(h, 100);
  EXPECT_EQ(r.images[3].width, 67);
  EXPECT_EQ(r.images[3].height, 100);
  for (const char* name : {"small.png", "small.jpg"}) {
    EXPECT_EQ(read_file_bytes(t / "out" / name), read_file_bytes(t / "in" / name)) << name;
  }
  EXPECT_FALSE(r.images[1].resized);
  // The downscaled quadrants keep their colours (area averaging, no shift).
  const Pixels p = read_rgb(t / "out" / "big.png");
  for (int c2 = 0; c2 < 3; ++c2) EXPECT_EQ(p.v[(size_t(10) * 100 + 10) * 3 + c2], kQuad[0][c2]);
}

TEST(Photos, FilesThatAreNotImagesAreListedAndImagesAreFoundByContent) {
  TempDir t;
  fs::create_directories(t / "in" / "sub");
  write(t / "in" / "notes.txt", {'h', 'i'});
  write(t / "in" / "fake.jpg", {'n', 'o', 't', ' ', 'a', ' ', 'j', 'p', 'g'});
  write(t / "in" / "photo_without_extension", jpeg_bytes(quadrants(16, 16)));
  write(t / "in" / "sub" / "nested.jpg", jpeg_bytes(quadrants(16, 16)));  // not recursive
  const InputReport r = import_photos(t / "in", t / "out", quiet());
  ASSERT_EQ(r.images.size(), 1u);
  EXPECT_EQ(r.images[0].name, "photo_without_extension");
  ASSERT_EQ(r.not_images.size(), 2u);
  EXPECT_EQ(fs::path(r.not_images[0]).filename(), "fake.jpg");
  EXPECT_EQ(fs::path(r.not_images[1]).filename(), "notes.txt");
  EXPECT_FALSE(fs::exists(t / "out" / "fake.jpg"));
}

TEST(Photos, TruncatedAndUndecodableFilesFailNamingTheFileOrAreSkipped) {
  TempDir t;
  fs::create_directories(t / "in");
  const auto good = jpeg_bytes(quadrants(64, 48));
  write(t / "in" / "a_good.jpg", good);
  std::vector<uint8_t> padded = good, trailer = good;
  padded.insert(padded.end(), 100, 0);  // zero padding after EOI (some cameras, some copies)
  for (char ch : std::string("motion photo video data after EOI")) trailer.push_back(uint8_t(ch));
  write(t / "in" / "b_padded.jpg", padded);
  write(t / "in" / "c_trailer.jpg", trailer);
  write(t / "in" / "d_cut.jpg", std::vector<uint8_t>(good.begin(), good.begin() + good.size() * 6 / 10));
  const auto png = encode_png_rgb(quadrants(64, 48));
  write(t / "in" / "e_cut.png", std::vector<uint8_t>(png.begin(), png.end() - 12));  // IEND gone
  std::vector<uint8_t> junk = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1A, '\n', 0, 0, 0, 0, 'I', 'E', 'N', 'D', 0, 0, 0, 0};
  write(t / "in" / "f_junk.png", junk);  // complete, but no image in it

  InputOptions opt = quiet();
  EXPECT_FILE_ERROR(
      import_photos(t / "in", t / "out", opt), t / "in" / "d_cut.jpg",
      "truncated JPEG (no end marker): copy it again or remove it from the folder (or --skip-bad-images)");
  EXPECT_FALSE(fs::exists(t / "out" / "d_cut.jpg"));
  fs::remove(t / "in" / "d_cut.jpg");
  EXPECT_FILE_ERROR(import_photos(t / "in", t / "out", opt), t / "in" / "e_cut.png", "truncated PNG (no IEND chunk)");
  fs::remove(t / "in" / "e_cut.png");
  EXPECT_FILE_ERROR(import_photos(t / "in", t / "out", opt), t / "in" / "f_junk.png", "cannot decode");

  write(t / "in" / "d_cut.jpg", std::vector<uint8_t>(good.begin(), good.begin() + good.size() / 2));
  opt.skip_bad = true;
  const InputReport r = import_photos(t / "in", t / "out", opt);
  ASSERT_EQ(r.images.size(), 3u);
  EXPECT_EQ(r.reused, 3) << "the good images a failing run converted are kept";
  EXPECT_EQ(r.images[2].name, "c_trailer.jpg");
  ASSERT_EQ(r.bad.size(), 2u);
  EXPECT_NE(r.bad[0].find("d_cut.jpg: truncated JPEG"), std::string::npos) << r.bad[0];
  EXPECT_NE(r.bad[1].find("f_junk.png: cannot decode"), std::string::npos) << r.bad[1];
  EXPECT_FALSE(fs::exists(t / "out" / "d_cut.jpg"));
  EXPECT_FALSE(fs::exists(t / "out" / "f_junk.png"));
}

TEST(Photos, ResumeKeepsDoneOutputsRedoesChangedOnesAndDropsRemovedOnes) {
  TempDir t;
  fs::create_directories(t / "in");
  for (int i = 0; i < 4; ++i)
    write(t / "in" / fmt::format("p{}.jpg", i), jpeg_bytes(quadrants(120, 80), i == 0 ? 6 : 0));
  const InputOptions opt = quiet(100);
  InputReport r = import_photos(t / "in", t / "out", opt);
  EXPECT_EQ(r.reused, 0);
  const auto stamp0 = fs::last_write_time(t / "out" / "p0.jpg");
  r = import_photos(t / "in", t / "out", opt);
  EXPECT_EQ(r.reused, 4);
  ASSERT_EQ(r.images.size(), 4u);
  EXPECT_EQ(r.images[0].orientation, 6);
  EXPECT_EQ(r.images[0].width, 67);
  EXPECT_EQ(fs::last_write_time(t / "out" / "p0.jpg"), stamp0);

  write(t / "in" / "p1.jpg", jpeg_bytes(quadrants(60, 40)));  // changed: now small enough to copy
  fs::remove(t / "in" / "p2.jpg");
  fs::remove(t / "out" / "p3.jpg");  // output lost
  atomic_write_text(t / "out" / "stray.txt", "not an output");
  r = import_photos(t / "in", t / "out", opt);
  EXPECT_EQ(r.reused, 1);
  ASSERT_EQ(r.images.size(), 3u);
  EXPECT_EQ(r.images[1].width, 60);
  EXPECT_EQ(read_file_bytes(t / "out" / "p1.jpg"), read_file_bytes(t / "in" / "p1.jpg"));
  EXPECT_FALSE(fs::exists(t / "out" / "p2.jpg")) << "the folder must equal the input";
  EXPECT_FALSE(fs::exists(t / "out" / "stray.txt"));
  EXPECT_TRUE(fs::exists(t / "out" / "p3.jpg"));

  r = import_photos(t / "in", t / "out", quiet(50));  // other options: nothing reused
  EXPECT_EQ(r.reused, 0);
  EXPECT_EQ(r.images[0].height, 50);
}

TEST(Photos, NamesThatDifferOnlyInCaseAndBadFoldersFailClearly) {
  TempDir t;
  fs::create_directories(t / "in");
  write(t / "in" / "a.JPG", jpeg_bytes(quadrants(16, 16)));
  write(t / "in" / "a.jpg", jpeg_bytes(quadrants(16, 16)));
  EXPECT_FILE_ERROR(import_photos(t / "in", t / "out", quiet()), t / "in", "a.JPG and a.jpg differ only in case");
  EXPECT_FILE_ERROR(import_photos(t / "missing", t / "out", quiet()), t / "missing", "not a folder");
  EXPECT_FILE_ERROR(import_photos(t / "in" / "a.jpg", t / "out", quiet()), t / "in" / "a.jpg", "not a folder");
  EXPECT_FILE_ERROR(import_photos(t / "in", t / "in", quiet()), t / "in", "may not be the photo folder");
  EXPECT_FALSE(fs::exists(t / "out")) << "nothing is written before the input is known to be usable";
}

// Issue 60, item 5: a name COLMAP cannot carry (backslash from a Windows-made archive, tab, newline, a trailing
// space) is written under a safe name, the renaming listed; the source keeps its name and a rerun reuses it.
TEST(Photos, NamesColmapCannotCarryAreRenamedAndListed) {
  TempDir t;
  fs::create_directories(t / "in");
  const std::vector<std::string> bad = {"a\\b.jpg", "c\td.jpg", "e\nf.jpg", "g.jpg "};
  for (const std::string& n : bad) write(t / "in" / n, jpeg_bytes(quadrants(16, 16)));
  write(t / "in" / "plain.jpg", jpeg_bytes(quadrants(16, 16)));
  InputReport r = import_photos(t / "in", t / "out", quiet());
  ASSERT_EQ(r.images.size(), 5u);
  std::set<std::string> names;
  for (const InputImage& im : r.images) names.insert(im.name);
  EXPECT_EQ(names, (std::set<std::string>{"a_b.jpg", "c_d.jpg", "e_f.jpg", "g.jpg_", "plain.jpg"}));
  for (const std::string& n : names) EXPECT_TRUE(fs::exists(t / "out" / n)) << n;
  ASSERT_EQ(r.renamed.size(), 4u);
  std::set<std::string> sources;
  for (const auto& [from, to] : r.renamed) sources.insert(fs::path(from).filename().string());
  EXPECT_EQ(sources, (std::set<std::string>(bad.begin(), bad.end())));
  r = import_photos(t / "in", t / "out", quiet());
  EXPECT_EQ(r.reused, 5);
  // A safe name that an existing photo already has: refused, naming both.
  write(t / "in" / "a_b.jpg", jpeg_bytes(quadrants(16, 16)));
  EXPECT_FILE_ERROR(import_photos(t / "in", t / "out", quiet()), t / "in", "would collide");
}

// Found by fuzz_prepare_input: a name that is not UTF-8 (an old archive's Latin-1 "caf\xe9.jpg") made writing the
// stage's record throw a JSON exception, and the run end in "internal error". It is renamed like the others,
// and the record (which keeps the source path) is written.
TEST(Photos, NamesThatAreNotUtf8AreRenamedAndTheRecordIsWritten) {
  TempDir t;
  fs::create_directories(t / "in");
  write(t / "in" / "caf\xe9.jpg", jpeg_bytes(quadrants(16, 16)));
  write(t / "in" / "ok\xc3\xa9.jpg", jpeg_bytes(quadrants(16, 16)));  // valid UTF-8 keeps its name
  InputReport r = import_photos(t / "in", t / "out", quiet());
  ASSERT_EQ(r.images.size(), 2u);
  std::set<std::string> names;
  for (const InputImage& im : r.images) names.insert(im.name);
  EXPECT_EQ(names, (std::set<std::string>{"caf_.jpg", "ok\xc3\xa9.jpg"}));
  ASSERT_EQ(r.renamed.size(), 1u);
  EXPECT_TRUE(fs::exists(t / "out" / "inputs.json"));
  EXPECT_NO_THROW(read_json_file(t / "out" / "inputs.json"));
  r = import_photos(t / "in", t / "out", quiet());
  EXPECT_EQ(r.images.size(), 2u);
}

// Issue 60, item 11: a link to nothing (dangling, or a loop) is skipped and listed wherever it sorts; the last
// entry used to fail the whole listing.
TEST(Photos, LinksToNothingAreSkippedAndListedWhereverTheySort) {
  TempDir t;
  fs::create_directories(t / "in");
  for (int i = 0; i < 3; ++i) write(t / "in" / fmt::format("p{}.jpg", i), jpeg_bytes(quadrants(16, 16)));
  fs::create_symlink(t / "nowhere.jpg", t / "in" / "a_dangling.jpg");
  fs::create_symlink(t / "in" / "p1_loop.jpg", t / "in" / "p1_loop.jpg");
  fs::create_symlink(t / "in" / "z_loop_b.jpg", t / "in" / "z_loop_a.jpg");
  fs::create_symlink(t / "in" / "z_loop_a.jpg", t / "in" / "z_loop_b.jpg");
  fs::create_symlink(t / "in" / "p0.jpg", t / "in" / "p3_link.jpg");  // a good link is a photo
  const InputReport r = import_photos(t / "in", t / "out", quiet());
  ASSERT_EQ(r.images.size(), 4u);
  EXPECT_EQ(r.images[3].name, "p3_link.jpg");
  ASSERT_EQ(r.broken_links.size(), 4u);
  EXPECT_EQ(fs::path(r.broken_links[0]).filename(), "a_dangling.jpg");
  EXPECT_EQ(fs::path(r.broken_links[3]).filename(), "z_loop_b.jpg");
  EXPECT_TRUE(r.not_images.empty());
}

// Issue 60, item 14: a zero-byte photo (an interrupted copy) is unreadable like a half-copied one: the run stops
// naming it, or it is skipped and listed with --skip-bad-images; it is not "not an image".
TEST(Photos, AnEmptyPhotoIsUnreadableLikeATruncatedOne) {
  TempDir t;
  fs::create_directories(t / "in");
  for (int i = 0; i < 3; ++i) write(t / "in" / fmt::format("p{}.jpg", i), jpeg_bytes(quadrants(16, 16)));
  write(t / "in" / "p1b.JPG", {});
  write(t / "in" / "empty_notes.txt", {});  // not named like an image: still not an image
  InputOptions opt = quiet();
  EXPECT_FILE_ERROR(import_photos(t / "in", t / "out", opt), t / "in" / "p1b.JPG", "empty file (0 bytes");
  opt.skip_bad = true;
  const InputReport r = import_photos(t / "in", t / "out", opt);
  EXPECT_EQ(r.images.size(), 3u);
  ASSERT_EQ(r.bad.size(), 1u);
  EXPECT_NE(r.bad[0].find("p1b.JPG: empty file"), std::string::npos) << r.bad[0];
  ASSERT_EQ(r.not_images.size(), 1u);
  EXPECT_EQ(fs::path(r.not_images[0]).filename(), "empty_notes.txt");
}

// A JPEG whose frame header declares w x h (the SOF0 of a small encoded image rewritten): a decompression bomb.
std::vector<uint8_t> jpeg_declaring(int w, int h) {
  std::vector<uint8_t> b = encode_jpeg(quadrants(16, 16), 90);
  for (size_t i = 2; i + 9 < b.size(); ++i)
    if (b[i] == 0xFF && b[i + 1] == 0xC0) {  // FF C0, length (2), precision (1), height (2), width (2)
      b[i + 5] = uint8_t(h >> 8), b[i + 6] = uint8_t(h), b[i + 7] = uint8_t(w >> 8), b[i + 8] = uint8_t(w);
      return b;
    }
  ADD_FAILURE() << "no SOF0 in the encoded JPEG";
  return b;
}

// Issue 60, item 13: a few KB declaring 16383 x 16383 (1.6 GB decoded) is refused from its header, before
// anything is allocated, by a limit the user can set; PNG too.
TEST(Photos, DecompressionBombsAreRefusedFromTheHeaderByASettableLimit) {
  const std::vector<uint8_t> bomb = jpeg_declaring(16383, 16383);
  ASSERT_LT(bomb.size(), 2000u);
  Pixels px;
  const std::string why = decode_rgb(bomb, px, kDefaultMaxPixels);
  EXPECT_NE(why.find("16383x16383"), std::string::npos) << why;
  EXPECT_NE(why.find("--max-pixels"), std::string::npos) << why;
  EXPECT_TRUE(px.v.empty());
  const auto png = encode_png_rgb(quadrants(64, 48));
  EXPECT_NE(decode_rgb(png, px, 64 * 48 - 1).find("64x48"), std::string::npos);
  EXPECT_EQ(decode_rgb(png, px, 64 * 48), "");
  EXPECT_EQ(px.width, 64);

  TempDir t;
  fs::create_directories(t / "in");
  for (int i = 0; i < 3; ++i) write(t / "in" / fmt::format("p{}.png", i), png);
  write(t / "in" / "bomb.jpg", bomb);
  InputOptions opt = quiet(32);
  EXPECT_FILE_ERROR(import_photos(t / "in", t / "out", opt), t / "in" / "bomb.jpg", "over the limit");
  opt.max_pixels = 64 * 48 - 1;  // (into a new folder: outputs kept from a run are not decoded again)
  fs::remove(t / "in" / "bomb.jpg");
  EXPECT_FILE_ERROR(import_photos(t / "in", t / "out2", opt), t / "in" / "p0.png", "--max-pixels");
  opt.max_pixels = 64 * 48;  // exactly the limit: every image, one at a time
  EXPECT_EQ(import_photos(t / "in", t / "out3", opt).images.size(), 3u);
}

}  // namespace
}  // namespace hgs::prepare
