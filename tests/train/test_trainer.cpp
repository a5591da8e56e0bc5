// Trainer: schedule scaling and the position learning rate, a tiny overfitting run that must reduce the loss,
// --no-densify keeping N, densification growing N, and checkpoint resume reproducing an uninterrupted run
// exactly (same thread count).
#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/error.h"
#include "core/fs.h"
#include "test_util.h"
#include "train/trainer.h"

namespace hgs::train {
namespace {

TEST(TrainConfig, ScaledSchedule) {
  TrainConfig c;
  TrainConfig s = c.scaled_to(30000);
  EXPECT_EQ(s.densify_from, 500);
  EXPECT_EQ(s.densify_until, 15000);
  EXPECT_EQ(s.densify_every, 100);
  EXPECT_EQ(s.opacity_reset_every, 3000);
  s = c.scaled_to(7000);
  EXPECT_EQ(s.iters, 7000);
  EXPECT_EQ(s.densify_from, 500);  // floor min(500, 700)
  EXPECT_EQ(s.densify_until, 3500);
  EXPECT_EQ(s.densify_every, 100);  // 23 raised to the floor
  EXPECT_EQ(s.opacity_reset_every, 1000);  // 700 raised to 10 intervals
  s = c.scaled_to(60000);
  EXPECT_EQ(s.densify_from, 1000);
  EXPECT_EQ(s.densify_every, 200);
  EXPECT_EQ(s.opacity_reset_every, 6000);
  s = c.scaled_to(1000);
  EXPECT_EQ(s.densify_from, 100);
  EXPECT_EQ(s.densify_until, 500);
  EXPECT_EQ(s.sh_increase_every, 1000);
}

TEST(TrainConfig, PositionLrDecaysLogLinearly) {
  TrainConfig c = TrainConfig().scaled_to(1000);
  EXPECT_NEAR(c.position_lr(0, 2.f), 3.2e-4f, 1e-9f);
  EXPECT_NEAR(c.position_lr(1000, 2.f), 3.2e-6f, 1e-11f);
  EXPECT_NEAR(c.position_lr(500, 2.f), 3.2e-5f, 1e-9f);  // geometric mean half way
  EXPECT_NEAR(c.position_lr(5000, 2.f), 3.2e-6f, 1e-11f);
  TrainConfig r = TrainConfig::from_json(c.to_json(), "test");
  EXPECT_EQ(r.to_json(), c.to_json());
  EXPECT_THROW(TrainConfig::from_json(nlohmann::json{{"iters", "many"}}, "x.json"), Error);
}

// A tiny problem: 40 Gaussians in front of a 32x24 camera, target = render of a different random model.
struct Tiny {
  std::vector<TrainView> views;
  GaussianModel model;
  Tiny(bool big_gaussians = false) {
    auto make = [&](unsigned seed) {
      GaussianModel m;
      m.sh_degree = 1;
      m.resize(40);
      std::mt19937 rng(seed);
      std::uniform_real_distribution<float> U(-1, 1);
      for (int i = 0; i < m.n; ++i) {
        m.mean[i * 3] = U(rng);
        m.mean[i * 3 + 1] = 0.7f * U(rng);
        m.mean[i * 3 + 2] = 3 + U(rng);
        for (int a = 0; a < 3; ++a) m.log_scale[i * 3 + a] = std::log(big_gaussians ? 0.4f : 0.15f) + 0.3f * U(rng);
        for (int a = 0; a < 4; ++a) m.quat[i * 4 + a] = U(rng);
        m.opacity_logit[i] = 2 * U(rng);
        for (int k = 0; k < 12; ++k) m.sh[i * 12 + k] = (k < 3 ? 1.f : 0.2f) * U(rng);
      }
      return m;
    };
    GaussianModel target = make(1);
    model = make(2);
    for (int v = 0; v < 3; ++v) {
      TrainView tv;
      tv.name = "v" + std::to_string(v);
      tv.cam.width = 32;
      tv.cam.height = 24;
      tv.cam.fx = tv.cam.fy = 30;
      tv.cam.cx = 16;
      tv.cam.cy = 12;
      tv.cam.t[0] = 0.2f * (v - 1);  // three slightly shifted cameras
      render::GaussianRenderer r;
      render::RenderOutputs out;
      render::GaussianInputs in;
      in.n = target.n;
      in.mean = target.mean.data();
      in.log_scale = target.log_scale.data();
      in.quat = target.quat.data();
      in.opacity_logit = target.opacity_logit.data();
      in.sh = target.sh.data();
      in.sh_stride = 4;
      in.sh_degree = 1;
      r.forward(tv.cam, in, {}, out);
      tv.image = Image(32, 24, 3);
      tv.image.px = out.rgb;
      views.push_back(std::move(tv));
    }
  }
};

TEST(Trainer, OverfitsTinyProblemWithFixedCount) {
  Tiny t;
  TrainConfig cfg = TrainConfig().scaled_to(300);
  cfg.densify = false;
  cfg.sh_degree = 1;
  Trainer tr(cfg, t.model, t.views, 1.f);
  double first = 0, last = 0;
  for (int i = 0; i < 300; ++i) {
    StepInfo s = tr.step();
    if (i < 3) first += s.loss.total;
    if (i >= 297) last += s.loss.total;
    EXPECT_EQ(s.num_gaussians, 40);
  }
  EXPECT_EQ(tr.iteration(), 300);
  // The step's parts are timed one after another inside it: none is negative and together they fit in it.
  const StepInfo s = tr.step();
  double parts = 0;
  StepTimes::each([&](const char* name, double StepTimes::*m) {
    EXPECT_GE(s.times.*m, 0.0) << name;
    parts += s.times.*m;
  });
  EXPECT_GT(s.times.forward, 0.0);
  EXPECT_LE(parts, s.ms + 1e-6);
  EXPECT_LT(last, 0.5 * first) << "loss did not halve: " << first / 3 << " -> " << last / 3;
}

TEST(Trainer, DensificationChangesCount) {
  Tiny t(true);
  TrainConfig cfg = TrainConfig().scaled_to(400);
  cfg.densify_from = 10;
  cfg.densify_every = 20;
  cfg.densify_cfg.grad_threshold = 1e-5f;  // low enough that large Gaussians split on this tiny problem
  Trainer tr(cfg, t.model, t.views, 1.f);
  int max_n = 40;
  for (int i = 0; i < 100; ++i) max_n = std::max(max_n, tr.step().num_gaussians);
  EXPECT_GT(max_n, 40);
  EXPECT_EQ(tr.adam().params[0].m.size(), size_t(tr.model().n) * 3);
}

TEST(Trainer, CheckpointResumeIsExact) {
  Tiny t(true);
  TrainConfig cfg = TrainConfig().scaled_to(60);
  cfg.densify_from = 5;
  cfg.densify_every = 10;
  cfg.densify_cfg.grad_threshold = 1e-5f;
  cfg.opacity_reset_every = 15;
  cfg.seed = 3;
  test::TempDir dir;
  Trainer a(cfg, t.model, t.views, 10.f);
  for (int i = 0; i < 23; ++i) a.step();
  a.save_checkpoint(dir / "c.ckpt");
  for (int i = 0; i < 30; ++i) a.step();

  Trainer b(cfg, t.model, t.views, 10.f);
  EXPECT_GT(a.model().n, 40);  // densification happened before and after the checkpoint
  b.load_checkpoint(dir / "c.ckpt");
  EXPECT_EQ(b.iteration(), 23);
  for (int i = 0; i < 30; ++i) b.step();
  ASSERT_EQ(a.model().n, b.model().n);
  EXPECT_EQ(a.model().mean, b.model().mean);
  EXPECT_EQ(a.model().sh, b.model().sh);
  EXPECT_EQ(a.model().opacity_logit, b.model().opacity_logit);
  EXPECT_EQ(a.adam().params[2].v, b.adam().params[2].v);
  for (size_t k = 0; k < a.adam().params.size(); ++k) EXPECT_EQ(a.adam().params[k].step, b.adam().params[k].step);

  // Damaged checkpoints give one-line errors.
  auto bytes = read_file_bytes(dir / "c.ckpt");
  atomic_write_bytes(dir / "short.ckpt", bytes.data(), bytes.size() - 100);
  Trainer c(cfg, t.model, t.views, 10.f);
  try {
    c.load_checkpoint(dir / "short.ckpt");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("short.ckpt: truncated checkpoint"), std::string::npos) << e.what();
  }
  atomic_write_text(dir / "bad.ckpt", "hello");
  EXPECT_THROW(c.load_checkpoint(dir / "bad.ckpt"), Error);
  EXPECT_EQ(c.iteration(), 0);  // failed loads leave the trainer untouched
}

}  // namespace
}  // namespace hgs::train
