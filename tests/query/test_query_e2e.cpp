// End to end through the CLI on a tiny synthetic scene: train Hybrid Gaussians, ask for objects by name,
// export one object, and evaluate with the instances protocol.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "model/ply.h"
#include "test_util.h"

using namespace hgs;
namespace fs = std::filesystem;

TEST(QueryEndToEnd, TrainQueryExportEval) {
  test::TempDir tmp;
  const std::string s = (tmp / "s").string(), m = (tmp / "m").string();
  auto r = test::run_hgs("synth --world simple --out " + s +
                         " --views 16 --width 128 --height 96 --objects 4 --points 3000 --noise low "
                         "--feature-dim 32 --supersample 1 --seed 5 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = test::run_hgs("train " + s + " --out " + m + " --iters 800 --sh-degree 1 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto objects = nlohmann::json::parse(read_file_text(tmp / "s" / "masks" / "objects.json"));
  int right = 0;
  for (auto& [id, name] : objects.items()) {
    const std::string out = (tmp / ("q" + id)).string();
    r = test::run_hgs("query " + s + " " + m + " --text \"" + name.get<std::string>() + "\" --out " + out + " --quiet");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    auto res = nlohmann::json::parse(read_file_text(fs::path(out) / "result.json"));
    right += res["queries"][0]["chosen"][0]["object"].get<int>() == std::stoi(id);
    // overlays exist for the held-out views
    EXPECT_TRUE(fs::exists(fs::path(out) / "frame_00001" / (name.get<std::string>() + ".overlay.png")) ||
                fs::exists(fs::path(out) / "frame_00001"));
  }
  EXPECT_GE(right, 3) << "of 4 objects found by name";
  r = test::run_hgs("export " + m + " --object 1 --out " + (tmp / "o1.ply").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  GaussianModel full = read_model_ply(tmp / "m" / "point_cloud.ply"), one = read_model_ply(tmp / "o1.ply");
  EXPECT_GT(one.n, 0);
  EXPECT_LT(one.n, full.n);
  r = test::run_hgs("export " + m + " --object 1 --remove --out " + (tmp / "no1.ply").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(read_model_ply(tmp / "no1.ply").n + one.n, full.n);
  r = test::run_hgs("eval " + s + " " + m + " --protocol instances --out " + (tmp / "e" / "report.json").string() +
                    " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto rep = nlohmann::json::parse(read_file_text(tmp / "e" / "report.json"));
  const double miou = rep["reports"][0]["summary"]["mIoU"].get<double>();
  std::printf("tiny scene, 800 iterations: object-mode mIoU %.3f\n", miou);
  EXPECT_GT(miou, 0.3);  // measured 0.44 (objects are only a few hundred pixels at 128x96)
  EXPECT_TRUE(fs::exists(tmp / "e" / "report.md"));
  // The pixel-mode report names its relevancy: hgs's object-embedding map by default, the others on request; the
  // paper's language map (LERF's relevancy, `--relevancy lerf`) is reported beside the default.
  ASSERT_EQ(rep["reports"].size(), 3u);
  EXPECT_EQ(rep["reports"][1]["mode"], "pixel");
  EXPECT_EQ(rep["reports"][1]["extra"]["relevancy"], "objects");
  EXPECT_EQ(rep["reports"][2]["mode"], "pixel-paper-map");
  EXPECT_EQ(rep["reports"][2]["extra"]["relevancy"], "lerf");
  EXPECT_NE(r.out.find("pixel mode: every pixel on its own: the text's cosine with hgs's object-embedding map"),
            std::string::npos)
      << r.out;  // what it measures
  EXPECT_NE(r.out.find("pixel-paper-map mode: every pixel on its own: LERF's relevancy of the paper's language map"),
            std::string::npos)
      << r.out;
  EXPECT_NE(read_file_text(tmp / "e" / "report.md").find("| pixel-paper-map | lerf |"), std::string::npos);
  EXPECT_FALSE(rep["reports"][0]["extra"].contains("relevancy"));
  r = test::run_hgs("eval " + s + " " + m + " --relevancy foreground --no-png --out " +
                    (tmp / "e2" / "report.json").string() + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto fg = nlohmann::json::parse(read_file_text(tmp / "e2" / "report.json"));
  EXPECT_EQ(fg["reports"][1]["extra"]["relevancy"], "foreground");
  EXPECT_EQ(fg["reports"][2]["mode"], "pixel-paper-map");
  r = test::run_hgs("eval " + s + " " + m + " --relevancy lerf --mode pixel --no-png --out " +
                    (tmp / "e3" / "report.json").string() + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto lerf = nlohmann::json::parse(read_file_text(tmp / "e3" / "report.json"));
  ASSERT_EQ(lerf["reports"].size(), 1u);  // the paper's map is pixel mode itself: no second report
  EXPECT_EQ(lerf["reports"][0]["extra"]["relevancy"], "lerf");
  // The figure beside the default is what `--relevancy lerf` alone gives, record for record (timings aside).
  auto untimed = [](nlohmann::json records) {
    for (auto& x : records) x.erase("seconds");
    return records;
  };
  ASSERT_GT(lerf["reports"][0]["records"].size(), 0u);
  EXPECT_EQ(untimed(lerf["reports"][0]["records"]), untimed(rep["reports"][2]["records"]));
  EXPECT_EQ(lerf["reports"][0]["summary"]["mIoU"], rep["reports"][2]["summary"]["mIoU"]);
  EXPECT_EQ(fg["reports"][2]["summary"]["mIoU"], rep["reports"][2]["summary"]["mIoU"]);
  r = test::run_hgs("eval " + s + " " + m + " --mode pixel --no-paper-map --no-png --out " +
                    (tmp / "e4" / "report.json").string() + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(read_file_text(tmp / "e4" / "report.json"))["reports"].size(), 1u);
  // Bad input: a model without object data.
  r = test::run_hgs("train " + s + " --out " + (tmp / "rgb").string() + " --method rgb --iters 20 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = test::run_hgs("query " + s + " " + (tmp / "rgb").string() + " --text x --out " + (tmp / "qq").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--method hybrid"), std::string::npos) << r.err;
}

TEST(QueryEndToEnd, PixelModeFollowsObjectModeInTheSamLikeWorld) {
  // Issue 36: on `hgs synth`'s default world (surfaces in the masks, parts, small objects missed) the pixel mode's
  // default score (the text's cosine with hgs's object-embedding map) stays near object mode, far above LERF's
  // relevancy of the paper's language map (LangSplat's scoring, which SCL's embeddings leave uncalibrated and
  // noisy).
  test::TempDir tmp;
  const std::string s = (tmp / "s").string(), m = (tmp / "m").string();
  auto r = test::run_hgs("synth --world simple --out " + s +
                         " --views 24 --width 160 --height 120 --feature-dim 64 --supersample 1 --seed 23 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = test::run_hgs("train " + s + " --out " + m + " --iters 1000 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto miou = [&](const std::string& name, const std::string& args) {
    const fs::path out = tmp / name / "report.json";
    auto e = test::run_hgs("eval " + s + " " + m + " --protocol instances --no-png --quiet " + args + " --out " +
                           out.string());
    EXPECT_EQ(e.exit_code, 0) << e.err;
    return nlohmann::json::parse(read_file_text(out))["reports"][0]["summary"]["mIoU"].get<double>();
  };
  const double object = miou("object", "--mode object"), pixel = miou("pixel", "--mode pixel"),
               raw = miou("raw", "--mode pixel --relevancy lerf");
  // Measured (seed 23, 1000 iterations; deterministic for a build, not across builds): the release build 0.899,
  // 0.795 and 0.197; the ASan + UBSan build (no AVX-512 clones, another trajectory) 0.911, 0.725 and 0.255. On
  // one scene pixel mode moves by whole masks (its per-query threshold keeps or drops an object in a view), so
  // the bound on pixel - object is the spread of the two builds; issue 59's goal (within 10 points) is measured
  // over scenes by bench/revalidate.sh, not here.
  std::printf("instances mIoU: object %.3f, pixel %.3f, pixel with the paper's map (LERF relevancy) %.3f\n", object,
              pixel, raw);
  EXPECT_GT(object, 0.75);
  EXPECT_GT(pixel, object - 0.2);
  EXPECT_GT(pixel, raw + 0.3);
}
