// The input stage on videos (prepare/photos.h import_video) and the blur rule (prepare/sharpness.h). The test
// video is made here: 30 frames of a sharp checkerboard under a grey strip whose level encodes the frame index,
// 4 of them box-blurred by ffmpeg, encoded losslessly (FFV1); the import must drop exactly those and keep the
// rest in order. Skipped when ffmpeg is missing.
#include <gtest/gtest.h>
#include <stb/stb_image.h>

#include <cmath>
#include <cstdlib>

#include "core/fs.h"
#include "expect_error.h"
#include "prepare/photos.h"
#include "prepare/pixels.h"
#include "prepare/run_tool.h"
#include "prepare/sharpness.h"
#include "test_util.h"

namespace hgs::prepare {
namespace {
namespace fs = std::filesystem;
using test::TempDir;

constexpr int kFrames = 30, kW = 160, kH = 120, kStripH = 30;
int strip_level(int i) { return 30 + 7 * i; }

#define REQUIRE_FFMPEG() \
  if (!find_program("ffmpeg")) GTEST_SKIP() << "ffmpeg is not installed (Debian's ffmpeg package): skipping"

// Frame i: the strip (rows < kStripH) at strip_level(i), below it a checkerboard of 4-pixel cells moved by i.
Pixels frame(int i) {
  Pixels p;
  p.width = kW, p.height = kH;
  p.v.resize(size_t(kW) * kH * 3);
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      const uint8_t v = y < kStripH ? uint8_t(strip_level(i)) : ((x + i) / 4 + y / 4) % 2 ? 230 : 20;
      for (int c = 0; c < 3; ++c) p.v[(size_t(y) * kW + x) * 3 + c] = v;
    }
  return p;
}

// A 10 fps video of kFrames frames with frames [blur_from, blur_to] box-blurred.
fs::path make_video(const TempDir& t, int blur_from, int blur_to) {
  fs::create_directories(t / "src");
  for (int i = 0; i < kFrames; ++i) {
    const auto b = encode_png_rgb(frame(i));
    atomic_write_bytes(t / "src" / fmt::format("f{:03d}.png", i), b.data(), b.size());
  }
  const fs::path video = t / "clip.mkv";
  const std::string cmd = fmt::format(
      "ffmpeg -nostdin -v error -y -framerate 10 -i '{}/f%03d.png' -vf \"boxblur=4:2:enable='between(n,{},{})'\" "
      "-c:v ffv1 '{}'",
      (t / "src").string(), blur_from, blur_to, video.string());
  EXPECT_EQ(std::system(cmd.c_str()), 0) << cmd;
  return video;
}

// The frame index a written frame shows (from its strip level).
int shown_index(const fs::path& p) {
  int w, h, c;
  uint8_t* d = stbi_load(p.c_str(), &w, &h, &c, 1);
  if (!d) return -1;
  const int level = d[size_t(kStripH / 3) * w + w / 2];
  stbi_image_free(d);
  return int(std::lround((level - 30) / 7.0));
}

InputOptions video_opt(double fps, int max_size) {
  InputOptions o;
  o.fps = fps;
  o.max_size = max_size;
  o.progress = false;
  return o;
}

TEST(Video, BlurredFramesAreDroppedAndTheRestKeptInOrder) {
  REQUIRE_FFMPEG();
  TempDir t;
  const fs::path video = make_video(t, 10, 13);
  const fs::path out = t / "scene" / "input";
  InputReport r = import_video(video, out, video_opt(10, 1600));
  ASSERT_EQ(r.images.size(), size_t(kFrames - 4));
  EXPECT_EQ(r.blurred.size(), 4u);
  std::vector<int> shown;
  for (size_t k = 0; k < r.images.size(); ++k) {
    EXPECT_EQ(r.images[k].name, fmt::format("frame_{:05d}.jpg", k + 1));
    EXPECT_EQ(r.images[k].width, kW);
    EXPECT_EQ(r.images[k].height, kH);
    shown.push_back(shown_index(out / r.images[k].name));
  }
  std::vector<int> expected;
  for (int i = 0; i < kFrames; ++i)
    if (i < 10 || i > 13) expected.push_back(i);
  EXPECT_EQ(shown, expected);
  EXPECT_TRUE(fs::exists(t / "scene" / "logs" / "ffmpeg.log"));
  EXPECT_FALSE(fs::exists(out / ".frames.tmp"));
  std::vector<std::string> files;
  for (const auto& e : fs::directory_iterator(out)) files.push_back(e.path().filename().string());
  EXPECT_EQ(files.size(), r.images.size() + 1) << "frames and inputs.json only";

  r = import_video(video, out, video_opt(10, 1600));  // same video, same options
  EXPECT_EQ(r.reused, kFrames - 4);
  EXPECT_EQ(r.blurred.size(), 4u);
}

TEST(Video, FpsAndMaxSizeAreApplied) {
  REQUIRE_FFMPEG();
  TempDir t;
  const fs::path video = make_video(t, 100, 100);  // nothing blurred
  const InputReport r = import_video(video, t / "in", video_opt(5, 80));
  EXPECT_TRUE(r.blurred.empty());
  ASSERT_GE(r.images.size(), 14u);
  ASSERT_LE(r.images.size(), 16u);
  int last = -1;
  for (const InputImage& im : r.images) {
    EXPECT_EQ(im.width, 80);
    EXPECT_EQ(im.height, 60);
    const int i = shown_index(t / "in" / im.name);
    EXPECT_GT(i, last) << im.name;
    last = i;
  }
}

TEST(Video, FilesFfmpegCannotReadAndAMissingFfmpegFailClearly) {
  REQUIRE_FFMPEG();
  TempDir t;
  atomic_write_text(t / "notes.txt", "not a video\n");
  EXPECT_FILE_ERROR(import_video(t / "notes.txt", t / "s" / "input", video_opt(2, 100)), t / "notes.txt",
                    (t / "s" / "logs" / "ffmpeg.log").string());
  InputOptions o = video_opt(2, 100);
  o.ffmpeg = "hgs-no-such-ffmpeg";
  EXPECT_FILE_ERROR(import_video(t / "notes.txt", t / "s" / "input", o), "hgs-no-such-ffmpeg",
                    "install Debian's ffmpeg package");
  o.ffmpeg = (t / "nowhere" / "ffmpeg").string();
  EXPECT_FILE_ERROR(import_video(t / "notes.txt", t / "s" / "input", o), o.ffmpeg, "--ffmpeg");
  EXPECT_FILE_ERROR(import_video(t / "missing.mp4", t / "s" / "input", video_opt(2, 100)), t / "missing.mp4",
                    "not a video file");
}

TEST(Video, VideoInputsAreFilesThatAreNotImages) {
  TempDir t;
  atomic_write_text(t / "clip.mp4", "whatever ffmpeg reads");
  const auto png = encode_png_rgb(frame(0));
  atomic_write_bytes(t / "still.mp4", png.data(), png.size());  // an image, whatever its name
  EXPECT_TRUE(is_video_input(t / "clip.mp4"));
  EXPECT_FALSE(is_video_input(t / "still.mp4"));
  EXPECT_FALSE(is_video_input(t.path));
  EXPECT_FALSE(is_video_input(t / "missing.mp4"));
}

TEST(Sharpness, LaplacianVarianceOfKnownImages) {
  std::vector<uint8_t> flat(8 * 6, 77), checker(8 * 6);  // [6, 8]
  for (int y = 0; y < 6; ++y)
    for (int x = 0; x < 8; ++x) checker[y * 8 + x] = (x + y) % 2 ? 255 : 0;
  EXPECT_EQ(laplacian_variance(flat.data(), 8, 6), 0.0);
  // Every interior Laplacian is +-4 x 255 and the two signs are equally common (6 x 4 interior pixels).
  EXPECT_DOUBLE_EQ(laplacian_variance(checker.data(), 8, 6), 1020.0 * 1020.0);
  EXPECT_EQ(laplacian_variance(checker.data(), 2, 2), 0.0);
}

TEST(Sharpness, FramesBelowTheLocalMedianAreDropped) {
  std::vector<double> s(20, 100.0);
  s[3] = 40, s[10] = 10, s[11] = 12, s[12] = 60;  // 60 >= 0.5 x 100 is kept
  const std::vector<bool> keep = keep_sharp_frames(s, 0.5);
  for (int i = 0; i < 20; ++i) EXPECT_EQ(keep[i], i != 3 && i != 10 && i != 11) << i;
  // A video soft throughout (a smooth trend) keeps every frame: the median follows it.
  std::vector<double> trend;
  for (int i = 0; i < 40; ++i) trend.push_back(1000.0 / (1 + i));
  for (bool k : keep_sharp_frames(trend, 0.5)) EXPECT_TRUE(k);
}

}  // namespace
}  // namespace hgs::prepare
