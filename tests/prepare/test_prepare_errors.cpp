// `hgs prepare` on bad input: each case exits non-zero with one line that says what to do, and leaves nothing
// that a rerun would take as complete (no prepare.json; the failed stage not marked done in prepare/state.json).
#include <fmt/format.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <fstream>
#include <nlohmann/json.hpp>
#include <random>

#include "core/image.h"
#include "prepare/run_tool.h"
#include "test_util.h"

namespace hgs::test {
namespace {
namespace fs = std::filesystem;

fs::path photos(const TempDir& t, int n, int w = 64, int h = 48) {
  const fs::path dir = t / "photos";
  fs::create_directories(dir);
  for (int i = 0; i < n; ++i) texture_png(dir / fmt::format("p{}.png", i), w, h, 7u + unsigned(i));
  return dir;
}

bool one_line(const std::string& s) { return std::count(s.begin(), s.end(), '\n') <= 1; }

bool stage_done(const fs::path& scene, const std::string& stage) {
  const fs::path f = scene / "prepare" / "state.json";
  if (!fs::exists(f)) return false;
  nlohmann::json j = nlohmann::json::parse(std::ifstream(f));
  return j.contains(stage) && j[stage].value("done", false);
}

TEST(PrepareErrors, MissingColmapNamesThePackage) {
  TempDir t;
  const fs::path in = photos(t, 3), out = t / "scene";
  RunResult r = run_hgs("prepare " + in.string() + " --out " + out.string() + " --colmap colmap-not-installed --quiet");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("colmap-not-installed not found"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("Debian's colmap package"), std::string::npos) << r.err;
  EXPECT_TRUE(one_line(r.err)) << r.err;
  EXPECT_FALSE(fs::exists(out / "prepare.json"));
  EXPECT_FALSE(stage_done(out, "features"));
}

TEST(PrepareErrors, FewerThanThreeImages) {
  TempDir t;
  const fs::path in = photos(t, 2), out = t / "scene";
  std::ofstream(in / "notes.txt") << "not an image\n";
  RunResult r = run_hgs("prepare " + in.string() + " --out " + out.string() + " --quiet");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("2 images found"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("at least 3"), std::string::npos) << r.err;
  EXPECT_TRUE(one_line(r.err)) << r.err;
  EXPECT_FALSE(fs::exists(out / "prepare.json"));
  EXPECT_FALSE(stage_done(out, "input"));
}

TEST(PrepareErrors, MissingInputAndForeignOutputFolder) {
  TempDir t;
  RunResult r = run_hgs("prepare " + (t / "nowhere").string() + " --out " + (t / "scene").string());
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("no such folder or video file"), std::string::npos) << r.err;
  const fs::path in = photos(t, 3), other = t / "other";
  fs::create_directories(other);
  std::ofstream(other / "keep.txt") << "user data\n";
  r = run_hgs("prepare " + in.string() + " --out " + other.string() + " --quiet");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("did not make"), std::string::npos) << r.err;
  EXPECT_TRUE(fs::exists(other / "keep.txt"));
  EXPECT_FALSE(fs::exists(other / "prepare"));
}

TEST(PrepareErrors, TruncatedImageIsNamedOrSkipped) {
  TempDir t;
  const fs::path in = photos(t, 4), out = t / "scene";
  const std::string bytes = [&] {
    std::ifstream f(in / "p1.png", std::ios::binary);
    return std::string(std::istreambuf_iterator<char>(f), {});
  }();
  std::ofstream(in / "p1.png", std::ios::binary | std::ios::trunc) << bytes.substr(0, bytes.size() / 2);
  RunResult r = run_hgs("prepare " + in.string() + " --out " + out.string() + " --quiet");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("p1.png"), std::string::npos) << r.err;
  EXPECT_TRUE(one_line(r.err)) << r.err;
  EXPECT_FALSE(fs::exists(out / "prepare.json"));
  r = run_hgs("prepare " + in.string() + " --out " + out.string() + " --skip-bad-images --until input --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  nlohmann::json j = nlohmann::json::parse(std::ifstream(out / "prepare.json"));
  EXPECT_EQ(j["input"]["images"], 3);
  ASSERT_EQ(j["input"]["bad"].size(), 1u);
  EXPECT_NE(j["input"]["bad"][0].get<std::string>().find("p1.png"), std::string::npos);
}

// A file size limit (RLIMIT_FSIZE, SIGXFSZ ignored) stands in for a full disk: the input stage's write fails
// with the file named; a rerun without the limit completes the stage.
TEST(PrepareErrors, FullDiskFailsCleanlyAndARerunCompletes) {
  TempDir t;
  const fs::path in = photos(t, 3, 160, 120), out = t / "scene";  // ~57 KB each
  const std::string cmd = std::string("bash -c \"trap '' XFSZ; ulimit -f 40; exec ") + HGS_BINARY + " prepare " +
                          in.string() + " --out " + out.string() + " --until input --quiet\" 2>" + (t / "err").string();
  const int st = std::system(cmd.c_str());
  EXPECT_NE(st, 0);
  std::ifstream ef(t / "err");
  const std::string err((std::istreambuf_iterator<char>(ef)), {});
  EXPECT_NE(err.find(".png"), std::string::npos) << err;
  EXPECT_TRUE(one_line(err)) << err;
  EXPECT_FALSE(fs::exists(out / "prepare.json"));
  EXPECT_FALSE(stage_done(out, "input"));
  RunResult r = run_hgs("prepare " + in.string() + " --out " + out.string() + " --until input --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(stage_done(out, "input"));
  for (int i = 0; i < 3; ++i) {
    int w = 0, h = 0;
    image_size(out / "prepare" / "input" / fmt::format("p{}.png", i), w, h);
    EXPECT_EQ(w, 160);
  }
}

// Images of two sizes (two cameras): one feature extraction per size, each with its own camera.
TEST(PrepareErrors, MixedSizesGetOneCameraPerSize) {
  if (!prepare::find_program("colmap")) GTEST_SKIP() << "colmap is not installed: skipping";
  TempDir t;
  const fs::path in = photos(t, 3, 96, 64), out = t / "scene";
  for (int i = 0; i < 3; ++i) texture_png(in / fmt::format("q{}.png", i), 80, 80, 100u + unsigned(i));
  RunResult r = run_hgs("prepare " + in.string() + " --out " + out.string() + " --until features --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ifstream a(out / "prepare" / "lists" / "images_96x64.txt"), b(out / "prepare" / "lists" / "images_80x80.txt");
  const std::string la((std::istreambuf_iterator<char>(a)), {}), lb((std::istreambuf_iterator<char>(b)), {});
  EXPECT_EQ(la, "p0.png\np1.png\np2.png\n");
  EXPECT_EQ(lb, "q0.png\nq1.png\nq2.png\n");
  std::ifstream log(out / "prepare" / "logs" / "features.log");
  const std::string l((std::istreambuf_iterator<char>(log)), {});
  EXPECT_EQ(std::count(l.begin(), l.end(), '$'), 2) << "one feature_extractor run per image size";
  EXPECT_TRUE(stage_done(out, "features"));
  EXPECT_FALSE(stage_done(out, "matching"));
}

// 12 real photos and 13 blank ones: fewer than half register, also after the wide-baseline retries (real COLMAP);
// refused with advice, kept with --allow-partial.
TEST(PrepareErrors, PartialRegistrationNeedsAllowPartial) {
  HGS_REQUIRE_SHARED(gc, "goldcape");
  if (!prepare::find_program("colmap")) GTEST_SKIP() << "colmap is not installed: skipping";
  TempDir t;
  const fs::path in = t / "photos", out = t / "scene";
  fs::create_directories(in);
  std::vector<fs::path> all;
  for (const auto& e : fs::directory_iterator(gc / "images")) all.push_back(e.path());
  std::sort(all.begin(), all.end());
  for (int i = 0; i < 12; ++i) fs::create_symlink(all[i], in / all[i].filename());
  for (int i = 0; i < 13; ++i) save_png(in / fmt::format("blank{}.png", i), Image(384, 288, 3, 0.5f));
  const std::string args =
      "prepare " + in.string() + " --out " + out.string() + " --max-size 512 --max-features 1024 --quiet";
  RunResult r = run_hgs(args);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("registered only"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("(retried: wide-baseline mapper: "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("; wide-baseline features: "), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--allow-partial"), std::string::npos) << r.err;
  EXPECT_TRUE(one_line(r.err)) << r.err;
  EXPECT_FALSE(fs::exists(out / "prepare.json"));
  EXPECT_FALSE(fs::exists(out / "sparse"));
  r = run_hgs(args + " --allow-partial");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  nlohmann::json j = nlohmann::json::parse(std::ifstream(out / "prepare.json"));
  EXPECT_LT(2 * j["poses"]["registered"].get<int>(), j["poses"]["images"].get<int>());
  EXPECT_TRUE(fs::exists(out / "sparse" / "0" / "images.bin"));
  for (const auto& st : j["stages"])
    if (st["stage"] == "mapping") {
      EXPECT_TRUE(st["reused"].get<bool>());
    }
}

}  // namespace
}  // namespace hgs::test
