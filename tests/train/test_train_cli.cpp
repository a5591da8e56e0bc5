// End to end through the `hgs` binary on a small synthetic scene (`hgs synth`, 24 views at 96x72, 2000 SfM
// points, LLFF split: 21 train / 3 test): RGB training converges to a stated test-view PSNR, outputs are
// complete and load back, --no-densify keeps the count, resume continues a run, bad input fails cleanly.
// Measured on this 2-core machine (1000 iterations, ~8 s): test PSNR 24.2 / 25.5 / 25.0 dB for scene seeds
// 1 / 2 / 3, ~6000 Gaussians; the test requires >= 22 dB.
#include <gtest/gtest.h>

#include <cstdlib>
#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "core/image.h"
#include "model/ply.h"
#include "test_util.h"

namespace hgs {
namespace {

nlohmann::json read_json(const std::filesystem::path& p) { return nlohmann::json::parse(read_file_text(p)); }

class TrainCli : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    setenv("OMP_WAIT_POLICY", "passive", 0);  // children should not spin on a shared 2-core machine
    dir_ = new test::TempDir;
    auto r = test::run_hgs("synth --world simple --out " + (dir_->path / "scene").string() +
                           " --seed 1 --views 24 --width 96 --height 72 --points 2000 --noise none --feature-dim 4"
                           " --supersample 1 --quiet");
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  static void TearDownTestSuite() { delete dir_; }
  static std::string scene() { return (dir_->path / "scene").string(); }
  static test::TempDir* dir_;
};
test::TempDir* TrainCli::dir_ = nullptr;

TEST_F(TrainCli, RgbConvergesAndWritesOutputs) {
  test::TempDir out;
  auto r = test::run_hgs("train " + scene() + " --method rgb --out " + (out / "m").string() +
                         " --iters 1000 --test-every 250 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto stats = read_json(out / "m" / "train_stats.json");
  // --test-every 250: the held-out score at 250, 500, 750 and 1000 images, against the training time so far.
  const auto& curve = stats["test_curve"];
  ASSERT_EQ(curve.size(), 4u) << curve.dump();
  for (size_t k = 0; k < 4; ++k) {
    EXPECT_EQ(curve[k]["iteration"], 250 * int(k + 1));
    if (k > 0) {
      EXPECT_GT(curve[k]["train_seconds"].get<double>(), curve[k - 1]["train_seconds"].get<double>());
    }
  }
  EXPECT_GT(curve[3]["test_psnr"].get<double>(), curve[0]["test_psnr"].get<double>() + 1.0);  // it learns
  EXPECT_LT(stats["test_seconds"].get<double>(), stats["wall_time_s"].get<double>());
  for (auto key :
       {"iterations", "median_ms_per_iter", "peak_rss_mb", "num_gaussians", "wall_time_s", "mean_ms_per_part"})
    EXPECT_TRUE(stats.contains(key)) << key;
  EXPECT_EQ(stats["iterations"], 1000);
  // The five slowest steps, slowest first, each with its densification part.
  const auto& slow = stats["slowest_steps"];
  ASSERT_EQ(slow.size(), 5u) << slow.dump();
  for (size_t k = 0; k < slow.size(); ++k) {
    if (k > 0) {
      EXPECT_GE(slow[k - 1]["ms"].get<double>(), slow[k]["ms"].get<double>());
    }
    EXPECT_LE(slow[k]["densify_ms"].get<double>(), slow[k]["ms"].get<double>());
    const int it = slow[k]["iteration"].get<int>();
    EXPECT_TRUE(it >= 1 && it <= 1000) << it;
  }
  EXPECT_GE(slow[0]["ms"].get<double>(), stats["median_ms_per_iter"].get<double>());
  auto cfg = read_json(out / "m" / "config.json");
  EXPECT_EQ(cfg["method"], "rgb");
  EXPECT_EQ(cfg["iters"], 1000);
  GaussianModel m = read_model_ply(out / "m" / "point_cloud.ply");
  EXPECT_EQ(m.n, stats["num_gaussians"].get<int>());
  EXPECT_EQ(m.sh_degree, 3);
  EXPECT_NE(m.n, cfg["init_points"].get<int>());  // densification changed the count

  r = test::run_hgs("render " + scene() + " " + (out / "m").string() + " --out " + (out / "r").string() + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto metrics = read_json(out / "r" / "metrics.json");
  EXPECT_EQ(metrics["num_views"], 3);
  ASSERT_EQ(metrics["views"].size(), 3u);
  double psnr = metrics["mean_psnr"].get<double>();
  EXPECT_NEAR(curve[3]["test_psnr"].get<double>(), psnr, 1e-4);  // the curve's last point is `hgs render`'s score
  EXPECT_GE(psnr, 22.0) << "test-view PSNR after 1000 iterations";
  EXPECT_GE(metrics["mean_ssim"].get<double>(), 0.75);
  std::string stem = metrics["views"][0]["name"].get<std::string>();
  stem = stem.substr(0, stem.rfind('.'));
  int w, h;
  image_size(out / "r" / "compare" / (stem + ".png"), w, h);
  EXPECT_EQ(w, 2 * 96);
  EXPECT_EQ(h, 72);
  image_size(out / "r" / "renders" / (stem + ".png"), w, h);
  EXPECT_EQ(w, 96);
}

// --near-plane: training writes it to config.json, `hgs render` culls at the config's value unless told another,
// and a bad value in config.json is a one-line error naming the file.
TEST_F(TrainCli, NearPlaneTravelsWithTheModel) {
  test::TempDir out;
  auto r = test::run_hgs("train " + scene() + " --method rgb --no-densify --iters 100 --near-plane 0.05 --out " +
                         (out / "m").string() + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto cfg = read_json(out / "m" / "config.json");
  EXPECT_FLOAT_EQ(cfg["near_plane"].get<float>(), 0.05f);
  auto render = [&](const std::string& name, const std::string& extra) {
    auto rr = test::run_hgs("render " + scene() + " " + (out / "m").string() + " --out " + (out / name).string() +
                            extra + " --quiet");
    EXPECT_EQ(rr.exit_code, 0) << rr.err;
    return read_json(out / name / "metrics.json");
  };
  const auto as_trained = render("r", "");
  EXPECT_FLOAT_EQ(as_trained["near_plane"].get<float>(), 0.05f);
  // The scene's cameras are about 1 unit from the objects: a near plane of 100 culls every Gaussian.
  const auto culled = render("far", " --near-plane 100");
  EXPECT_FLOAT_EQ(culled["near_plane"].get<float>(), 100.f);
  EXPECT_LT(culled["mean_psnr"].get<double>(), as_trained["mean_psnr"].get<double>() - 3.0);
  cfg["near_plane"] = 100.0;
  atomic_write_text(out / "m" / "config.json", cfg.dump(2));
  const auto from_config = render("cfg", "");
  EXPECT_EQ(from_config["mean_psnr"], culled["mean_psnr"]);  // the config's value, as the flag's
  cfg["near_plane"] = -1.0;
  atomic_write_text(out / "m" / "config.json", cfg.dump(2));
  r = test::run_hgs("render " + scene() + " " + (out / "m").string() + " --out " + (out / "bad").string() + " --quiet");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("config.json"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("near plane"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out / "bad" / "metrics.json"));
}

TEST_F(TrainCli, NoDensifyKeepsCountAndResumeContinues) {
  test::TempDir out;
  auto r = test::run_hgs("train " + scene() + " --method rgb --no-densify --save-every 100 --iters 200 --out " +
                         (out / "m").string() + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto cfg = read_json(out / "m" / "config.json");
  EXPECT_EQ(read_model_ply(out / "m" / "point_cloud.ply").n, cfg["init_points"].get<int>());
  EXPECT_TRUE(std::filesystem::exists(out / "m" / "checkpoints" / "iter_100.ckpt"));
  ASSERT_TRUE(std::filesystem::exists(out / "m" / "checkpoints" / "iter_200.ckpt"));
  r = test::run_hgs("train " + scene() + " --method rgb --no-densify --iters 300 --resume " +
                    (out / "m" / "checkpoints" / "iter_200.ckpt").string() + " --out " + (out / "m2").string() +
                    " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto stats = read_json(out / "m2" / "train_stats.json");
  EXPECT_EQ(stats["iterations"], 300);
  EXPECT_EQ(stats["iterations_this_run"], 100);
}

TEST_F(TrainCli, BadInputFailsCleanly) {
  test::TempDir out;
  auto r = test::run_hgs("train " + (out / "nope").string() + " --method rgb --out " + (out / "m").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("hgs: error:"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("nope"), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out / "m" / "point_cloud.ply"));

  atomic_write_text(out / "bad.ply", "ply\nformat ascii 1.0\nelement vertex 1\nend_header\n");
  r = test::run_hgs("render " + scene() + " " + (out / "bad.ply").string() + " --out " + (out / "r").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("bad.ply: ASCII PLY is not supported"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out / "r" / "metrics.json"));

  r = test::run_hgs("train " + scene() + " --method rgb --out " + (out / "m").string() + " --resume " +
                    (out / "bad.ply").string() + " --iters 10 --quiet");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("not an hgs checkpoint"), std::string::npos) << r.err;

  for (auto cmd : {"train --help", "render --help"}) {
    r = test::run_hgs(cmd);
    EXPECT_EQ(r.exit_code, 0);
    EXPECT_NE(r.out.find("Usage"), std::string::npos);
  }
}

}  // namespace
}  // namespace hgs
