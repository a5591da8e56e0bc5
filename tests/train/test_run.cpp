// train::TrainingRun, the one training run of `hgs train`, `hgs ablate`, the depth model and hgs.train: the callback
// sees every step and can end the run (with its reason in train_stats.json), the model folder is complete after a stop,
// checkpoints come at their cadence and resume to the same model, and runs that cannot go as asked fail before writing
// anything.
#include <gtest/gtest.h>

#include <cstdlib>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fs.h"
#include "model/ply.h"
#include "scene/scene.h"
#include "test_util.h"
#include "train/registry.h"
#include "train/run.h"

namespace hgs::train {
namespace {
namespace fs = std::filesystem;
using nlohmann::json;

class RunTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    setenv("OMP_WAIT_POLICY", "passive", 0);
    dir_ = new test::TempDir;
    auto r = test::run_hgs("synth --world simple --out " + (dir_->path / "scene").string() +
                           " --seed 2 --views 8 --width 48 --height 36 --points 400 --noise none --feature-dim 4"
                           " --supersample 1 --quiet");
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  static void TearDownTestSuite() { delete dir_; }
  static Scene scene() { return load_scene(dir_->path / "scene", {1, false}); }
  static std::unique_ptr<Trainer> trainer(const Scene& s, int iters) {
    TrainConfig cfg = TrainConfig{}.scaled_to(iters);
    cfg.densify = false;
    return make_trainer(s, s.train_indices(), cfg, "rgb", nullptr, false);
  }
  static test::TempDir* dir_;
};
test::TempDir* RunTest::dir_ = nullptr;

json read_json(const fs::path& p) { return json::parse(read_file_text(p)); }

TEST_F(RunTest, CallbackSeesEveryStepAndStopsTheRunWithItsReason) {
  const Scene s = scene();
  auto t = trainer(s, 50);
  test::TempDir out;
  RunOptions ro;
  ro.out = out / "m";
  TrainingRun run(*t, s, ro, run_config(*t, s, nullptr, t->model().n));
  // config.json is there before the first step.
  ASSERT_TRUE(fs::exists(out / "m" / "config.json"));
  EXPECT_FALSE(fs::exists(out / "m" / "point_cloud.ply"));
  std::vector<int> seen;
  run.train([&](const RunStep& st) {
    seen.push_back(st.iteration);
    EXPECT_EQ(st.start, 0);
    EXPECT_EQ(st.iters, 50);
    EXPECT_TRUE(std::isfinite(st.average.loss));
    if (st.iteration == 7) run.stop_reason("interrupted");
    return st.iteration < 7;
  });
  EXPECT_EQ(seen, (std::vector<int>{1, 2, 3, 4, 5, 6, 7}));
  EXPECT_EQ(run.stopped(), "interrupted");
  run.save();
  const json stats = read_json(out / "m" / "train_stats.json");
  EXPECT_EQ(stats["stopped"], "interrupted");
  EXPECT_EQ(stats["iterations"], 7);
  EXPECT_EQ(stats["iterations_this_run"], 7);
  for (const char* key :
       {"median_ms_per_iter", "mean_ms_per_iter", "peak_rss_mb", "num_gaussians", "wall_time_s", "test_seconds",
        "test_curve", "final_train_loss_ema", "final_train_loss_terms_ema", "final_train_psnr_ema", "threads", "ranks",
        "views_per_step", "slowest_steps", "mean_ms_per_part", "median_ms_per_part", "comm_bytes_per_step"})
    EXPECT_TRUE(stats.contains(key)) << key;
  // Each part's median over the 7 steps lies within its steps' range, so at most 7 times its mean; a step
  // renders, so the forward's median is positive.
  for (const auto& [name, mean] : stats["mean_ms_per_part"].items()) {
    ASSERT_TRUE(stats["median_ms_per_part"].contains(name)) << name;
    const double median = stats["median_ms_per_part"][name].get<double>();
    EXPECT_GE(median, 0.0) << name;
    EXPECT_LE(median, 7 * mean.get<double>() + 1e-9) << name;
  }
  EXPECT_GT(stats["median_ms_per_part"]["forward"].get<double>(), 0.0);
  EXPECT_EQ(read_model_ply(out / "m" / "point_cloud.ply").n, t->model().n);
  const json config = read_json(out / "m" / "config.json");
  EXPECT_EQ(config["iters"], 50);
  EXPECT_EQ(config["train_views"], t->views().size());
  EXPECT_EQ(config["ranks"], 1);
  EXPECT_FALSE(config.contains("resumed_from"));
}

TEST_F(RunTest, ARunToTheEndRecordsNoStopAndCheckpointsResumeToTheSameModel) {
  const Scene s = scene();
  test::TempDir out;
  auto full = trainer(s, 20);
  RunOptions ro;
  ro.out = out / "full";
  ro.save_every = 10;
  TrainingRun run(*full, s, ro, run_config(*full, s, nullptr, full->model().n));
  run.train();
  EXPECT_EQ(run.stopped(), "");
  EXPECT_TRUE(run.save()["stopped"].is_null());
  EXPECT_TRUE(fs::exists(out / "full" / "checkpoints" / "iter_10.ckpt"));
  EXPECT_TRUE(fs::exists(out / "full" / "point_cloud_iter_10.ply"));
  EXPECT_TRUE(fs::exists(out / "full" / "checkpoints" / "iter_20.ckpt"));  // the final one

  auto resumed = trainer(s, 20);
  const int init = resumed->model().n;
  const std::string ckpt = (out / "full" / "checkpoints" / "iter_10.ckpt").string();
  resumed->load_checkpoint(ckpt);
  RunOptions rr;
  rr.out = out / "resumed";
  rr.resumed_from = ckpt;
  TrainingRun again(*resumed, s, rr, run_config(*resumed, s, nullptr, init));
  again.train();
  const json stats = again.save();
  EXPECT_EQ(stats["iterations_this_run"], 10);
  EXPECT_EQ(read_json(out / "resumed" / "config.json")["resumed_from"], ckpt);
  EXPECT_EQ(read_file_text(out / "resumed" / "point_cloud.ply"), read_file_text(out / "full" / "point_cloud.ply"));
}

TEST_F(RunTest, RunsThatCannotGoAsAskedFailBeforeWritingAnything) {
  const Scene s = scene();
  test::TempDir out;
  auto t = trainer(s, 20);
  const json config = run_config(*t, s, nullptr, t->model().n);
  RunOptions no_out;
  no_out.save_every = 10;
  EXPECT_THROW(TrainingRun(*t, s, no_out, config), Error);  // checkpoints need a folder
  RunOptions ro;
  ro.out = out / "m";
  ro.iters = 10;
  ro.save_every = 10;
  TrainingRun(*t, s, ro, config).train();
  RunOptions done = ro;
  done.out = out / "done";
  try {
    TrainingRun(*t, s, done, config);  // the trainer is at 10 of 10 images
    FAIL() << "expected an error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("nothing to do"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(out / "done"));
}

TEST_F(RunTest, FinalFilesAreWrittenWholeOrNotAtAll) {
  // The end of a run writes point_cloud.ply, the last checkpoint and train_stats.json as one change of the folder
  // (core/folder.h). A write that fails part way (here train_stats.json, made a folder so it cannot be replaced;
  // as a full disk or a second Ctrl-C would) leaves the folder as it was: no point_cloud.ply without its stats.
  const Scene s = scene();
  auto t = trainer(s, 4);
  test::TempDir out;
  RunOptions ro;
  ro.out = out / "m";
  ro.save_every = 2;
  TrainingRun run(*t, s, ro, run_config(*t, s, nullptr, t->model().n));
  run.train();
  fs::create_directories(out / "m" / "train_stats.json");
  const std::string e = test::error_of([&] { run.save(); });
  EXPECT_NE(e.find("train_stats.json"), std::string::npos) << e;
  EXPECT_FALSE(fs::exists(out / "m" / "point_cloud.ply"));
  EXPECT_FALSE(fs::exists(out / "m" / "checkpoints" / "iter_4.ckpt"));
  EXPECT_TRUE(fs::exists(out / "m" / "checkpoints" / "iter_2.ckpt"));  // what was there is kept
  EXPECT_TRUE(fs::exists(out / "m" / "config.json"));
  // Nothing beside the folder either.
  EXPECT_EQ(std::distance(fs::directory_iterator(out.path), fs::directory_iterator()), 1);
  fs::remove(out / "m" / "train_stats.json");
  run.save();
  EXPECT_TRUE(fs::exists(out / "m" / "point_cloud.ply"));
  EXPECT_TRUE(fs::exists(out / "m" / "checkpoints" / "iter_4.ckpt"));
  EXPECT_EQ(read_json(out / "m" / "train_stats.json")["iterations"], 4);
  EXPECT_TRUE(fs::exists(out / "m" / "checkpoints" / "iter_2.ckpt"));
}

}  // namespace
}  // namespace hgs::train
