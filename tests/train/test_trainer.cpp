// Trainer: schedule scaling and the position learning rate, a tiny overfitting run that must reduce the loss,
// --no-densify keeping N, densification growing N, and checkpoint resume reproducing an uninterrupted run
// exactly (same thread count); the Method seam: hook order, weighted terms in the objective, a method's
// registered parameters (per-Gaussian and array) through densification and checkpoints.
#include <gtest/gtest.h>

#include <algorithm>
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
  EXPECT_EQ(s.densify_every, 100);         // 23 raised to the floor
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
  EXPECT_THROW(TrainConfig::from_json(nlohmann::json{{"batch_lr", "linear"}}, "x.json"), Error);
  EXPECT_EQ(TrainConfig::from_json(nlohmann::json{{"batch_lr", "sqrt-rates"}}, "x.json").batch_lr, "sqrt-rates");
  // The near plane travels with the configuration (MODEL/config.json, checkpoints); absent, gsplat's 0.01.
  EXPECT_EQ(TrainConfig::from_json(nlohmann::json{{"near_plane", 0.2}}, "x.json").near_plane, 0.2f);
  EXPECT_EQ(TrainConfig::from_json(nlohmann::json::object(), "x.json").near_plane, 0.01f);
  EXPECT_THROW(TrainConfig::from_json(nlohmann::json{{"near_plane", 0}}, "x.json"), Error);
  EXPECT_THROW(TrainConfig::from_json(nlohmann::json{{"near_plane", -0.2}}, "x.json"), Error);
  // The late prune's footprint limit likewise; absent (models before it), off.
  EXPECT_EQ(TrainConfig::from_json(nlohmann::json{{"late_prune", 0.5}}, "x.json").late_prune, 0.5f);
  EXPECT_EQ(TrainConfig::from_json(nlohmann::json::object(), "x.json").late_prune, 0.f);
  EXPECT_THROW(TrainConfig::from_json(nlohmann::json{{"late_prune", -1}}, "x.json"), Error);
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

// TrainConfig::late_prune: after densify_until the prune goes on every densify_every images (no clone, split,
// opacity reset or world-size rule: with extent 1 that rule would prune every Gaussian of this problem), with the
// footprint limit a fraction of the views' larger side; without it the count is frozen there. Both runs are the
// same step for step before the first late prune.
TEST(Trainer, LatePruneKeepsPruningOversizedGaussiansAfterDensificationStops) {
  Tiny t(true);
  TrainConfig cfg = TrainConfig().scaled_to(100);
  cfg.sh_degree = 1;
  cfg.densify_from = 10;
  cfg.densify_every = 20;
  cfg.densify_until = 40;
  cfg.opacity_reset_every = 1000;          // no opacity reset
  cfg.densify_cfg.grad_threshold = 1e30f;  // nothing clones or splits
  cfg.screen_limit = 1e30f;                // while growing nothing is pruned by size
  std::vector<int> counts[2];
  std::vector<double> losses[2];
  for (int late = 0; late < 2; ++late) {
    TrainConfig c = cfg;
    c.late_prune = late ? 20.f / 32.f : 0.f;  // 20 px of 32 x 24 views (footprints 6-24 px at the start)
    Trainer tr(c, t.model, t.views, 1.f);
    for (int i = 0; i < 100; ++i) {
      const StepInfo s = tr.step();
      counts[late].push_back(s.num_gaussians);
      losses[late].push_back(s.loss.total);
      const int it = i + 1;  // growing at 20 (densify_until 40 is exclusive), the prune alone at 40, 60, 80, 100
      EXPECT_EQ(s.densified, it == 20 || (late && it % 20 == 0)) << "image " << it;
    }
  }
  EXPECT_EQ(counts[0], std::vector<int>(100, 40));
  for (int i = 0; i < 39; ++i) {  // up to the step of image 40, whose prune follows its update
    EXPECT_EQ(counts[1][i], 40) << i;
    EXPECT_EQ(losses[1][i], losses[0][i]) << i;
  }
  EXPECT_LT(counts[1][39], 40);
  EXPECT_GT(counts[1].back(), 0) << counts[1][39] << " " << counts[1][59] << " " << counts[1][79];
  for (int i = 1; i < 100; ++i) EXPECT_LE(counts[1][i], counts[1][i - 1]) << i;
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

namespace hgs::train {
namespace {

// A method that records the order of its calls, owns a per-Gaussian parameter "probe" (model extra group,
// pulled towards 1) and an array parameter "bias" [2] (pulled towards (3, -2)), both in the trainer's optimiser.
struct Probe : Method {
  std::vector<std::string> calls;
  std::vector<float> bias = {0.f, 0.f}, dbias, dprobe;
  GaussianModel* model = nullptr;
  double last_value = 0;
  std::string name() const override { return "probe"; }
  void attach(GaussianModel& m, Adam& optim, const std::vector<TrainView>& /*views*/) override {
    model = &m;
    ExtraGroup& g = m.add_extra("probe", 1, 0.f);
    for (int i = 0; i < m.n; ++i) g.data[i] = float(i);
    optim.add("probe", 1, m.n, 0.1f).values = [this] {
      return ParamValues{&model->find_extra("probe")->data, nullptr};
    };
    optim.add_array("bias", 1, 2, 0.1f).values = [this] { return ParamValues{&bias, nullptr}; };
  }
  float rgb_weight() const override { return 0.5f; }
  void prepare(const ViewStep&, const PrepareIO&) override { calls.push_back("prepare"); }
  void losses(const ViewStep& v, const LossIO& io) override {
    calls.push_back("losses");
    const float t[2] = {3.f, -2.f};
    double value = 0;
    dbias.resize(2);
    for (int k = 0; k < 2; ++k) {
      value += double(bias[k] - t[k]) * (bias[k] - t[k]);
      dbias[k] = 0.25f * 2 * (bias[k] - t[k]);  // weight 0.25
    }
    const std::vector<float>& p = v.model.find_extra("probe")->data;
    dprobe.resize(p.size());
    for (size_t i = 0; i < p.size(); ++i) dprobe[i] = p[i] - 1.f;
    last_value = value;
    io.objective.add("probe", 0.25f, value);
  }
  void backward(const ViewStep&, const BackwardIO&) override { calls.push_back("backward"); }
  void update(const UpdateIO& io) override {
    calls.push_back("update");
    io.optim.update(io.optim.get("bias"), bias.data(), dbias.data(), 2);
    io.optim.update(io.optim.get("probe"), io.model.find_extra("probe")->data.data(), dprobe.data(), io.model.n);
  }
  void after_step(const StepEnd& end) override { calls.push_back(end.densified ? "densified" : "after_step"); }
};

TEST(Method, HooksRunInOrderAndTheirTermsAreOptimised) {
  Tiny t;
  TrainConfig cfg = TrainConfig().scaled_to(100);
  cfg.densify = false;
  auto probe = std::make_unique<Probe>();
  Probe& p = *probe;
  Trainer tr(cfg, t.model, t.views, 1.f, std::move(probe));
  StepInfo s = tr.step();
  EXPECT_EQ(p.calls, (std::vector<std::string>{"prepare", "losses", "backward", "update", "after_step"}));
  ASSERT_EQ(s.terms.size(), 2u);
  EXPECT_EQ(s.terms[0].name, "rgb");
  EXPECT_EQ(s.terms[0].weight, 0.5f);
  EXPECT_EQ(s.terms[0].value, s.loss.total);
  EXPECT_EQ(s.terms[1].name, "probe");
  EXPECT_DOUBLE_EQ(s.total, 0.5 * s.loss.total + 0.25 * p.last_value);
  for (int i = 0; i < 200; ++i) tr.step();
  EXPECT_NEAR(p.bias[0], 3.f, 0.05f);  // the method's array parameter is optimised by the shared Adam
  EXPECT_NEAR(p.bias[1], -2.f, 0.05f);
  EXPECT_EQ(tr.adam().params.back().step, 201);  // its own step count
}

TEST(Method, RegisteredParametersFollowDensificationAndCheckpoints) {
  Tiny t(true);
  TrainConfig cfg = TrainConfig().scaled_to(60);
  cfg.densify_from = 5;
  cfg.densify_every = 10;
  cfg.densify_cfg.grad_threshold = 1e-5f;
  cfg.seed = 3;
  test::TempDir dir;
  auto make = [&] { return std::make_unique<Trainer>(cfg, t.model, t.views, 1.f, std::make_unique<Probe>()); };
  auto a = make();
  auto& pa = dynamic_cast<Probe&>(a->method());
  for (int i = 0; i < 23; ++i) a->step();
  EXPECT_NE(a->model().n, 40);  // densified
  EXPECT_NE(std::find(pa.calls.begin(), pa.calls.end(), "densified"), pa.calls.end());
  const AdamParam& probe = *a->adam().find("probe");
  const AdamParam& bias = *a->adam().find("bias");
  EXPECT_EQ(probe.m.size(), size_t(a->model().n));  // per-Gaussian moments follow the Gaussians
  EXPECT_EQ(bias.m.size(), 2u);                     // the array parameter is left alone
  EXPECT_EQ(a->model().find_extra("probe")->data.size(), size_t(a->model().n));
  a->save_checkpoint(dir / "p.ckpt");
  for (int i = 0; i < 20; ++i) a->step();
  auto b = make();
  auto& pb = dynamic_cast<Probe&>(b->method());
  b->load_checkpoint(dir / "p.ckpt");
  EXPECT_NE(pb.bias[0], 0.f);  // restored from the checkpoint without per-method code
  for (int i = 0; i < 20; ++i) b->step();
  EXPECT_EQ(pa.bias, pb.bias);
  EXPECT_EQ(a->model().find_extra("probe")->data, b->model().find_extra("probe")->data);
  for (size_t k = 0; k < a->adam().params.size(); ++k) {
    EXPECT_EQ(a->adam().params[k].step, b->adam().params[k].step) << a->adam().params[k].name;
    EXPECT_EQ(a->adam().params[k].v, b->adam().params[k].v) << a->adam().params[k].name;
  }
  // A plain 3DGS trainer cannot load it (and says why).
  Trainer c(cfg, t.model, t.views, 1.f);
  try {
    c.load_checkpoint(dir / "p.ckpt");
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("trained with the probe method, not rgb"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace hgs::train

namespace hgs::train {
namespace {

// Records the 3DGS gradient the update step sees (after the batch mean), the views of each step, and
// densification.
struct GradTap : Method {
  std::vector<float> mean_grad, sh_grad;
  std::vector<int> views, step_views;
  std::vector<int> densified_at;  // iteration() after the steps that densified
  const Trainer* tr = nullptr;
  std::string name() const override { return "tap"; }
  void prepare(const ViewStep& v, const PrepareIO&) override { views.push_back(v.view_index); }
  void update(const UpdateIO& io) override {
    mean_grad = io.grads.mean;
    sh_grad = io.grads.sh;
    step_views.push_back(io.step_views);
  }
  void after_step(const StepEnd& end) override {
    if (end.densified) densified_at.push_back(end.images_seen);
  }
};

TEST(TrainerBatch, StepGradientIsTheMeanOfItsViews) {
  Tiny t;
  TrainConfig cfg = TrainConfig().scaled_to(100);
  cfg.densify = false;
  auto grad_of = [&](std::vector<TrainView> views, int batch) {
    TrainConfig c = cfg;
    c.batch = batch;
    auto tap = std::make_unique<GradTap>();
    GradTap& g = *tap;
    Trainer tr(c, t.model, std::move(views), 1.f, std::move(tap));
    tr.step();
    EXPECT_EQ(tr.iteration(), batch);
    return std::make_pair(g.mean_grad, g.sh_grad);
  };
  const auto a = grad_of({t.views[0]}, 1), b = grad_of({t.views[2]}, 1), ab = grad_of({t.views[0], t.views[2]}, 2);
  ASSERT_EQ(ab.first.size(), a.first.size());
  int differ = 0;
  for (size_t k = 0; k < a.first.size(); ++k) {
    EXPECT_EQ(ab.first[k], (a.first[k] + b.first[k]) * 0.5f) << k;  // two addends: exact in either order
    differ += a.first[k] != b.first[k];
  }
  EXPECT_GT(differ, 0) << "the two views' gradients should differ";
  for (size_t k = 0; k < a.second.size(); ++k) EXPECT_EQ(ab.second[k], (a.second[k] + b.second[k]) * 0.5f) << k;
}

TEST(TrainerBatch, TwoCopiesOfAViewStepLikeTheViewAlone) {
  Tiny t;
  TrainConfig cfg = TrainConfig().scaled_to(100);
  cfg.densify = false;
  Trainer one(cfg, t.model, {t.views[1]}, 1.f);
  cfg.batch = 2;
  Trainer two(cfg, t.model, {t.views[1], t.views[1]}, 1.f);
  one.step();
  two.step();  // mean of two equal gradients = the gradient; the same learning rates (images 1-2 start at 1)
  EXPECT_EQ(one.model().mean, two.model().mean);
  EXPECT_EQ(one.model().sh, two.model().sh);
  EXPECT_EQ(one.model().opacity_logit, two.model().opacity_logit);
}

TEST(TrainerBatch, SqrtRuleScalesTheRatesBySqrtGAndRaisesTheBetasToG) {
  // --batch-lr sqrt (Grendel): rates x sqrt(G), betas^G. Adam's first step is lr x sign(g) whatever the betas
  // (the bias correction cancels them), so the first step of the sqrt rule is sqrt(2) times the plain one.
  Tiny t;
  TrainConfig cfg = TrainConfig().scaled_to(100);
  cfg.densify = false;
  cfg.batch = 2;
  Trainer plain(cfg, t.model, {t.views[1], t.views[1]}, 1.f);
  cfg.batch_lr = "sqrt";
  Trainer sq(cfg, t.model, {t.views[1], t.views[1]}, 1.f);
  EXPECT_FLOAT_EQ(sq.adam().lr_scale, std::sqrt(2.f));
  EXPECT_FLOAT_EQ(sq.adam().beta1, 0.81f);
  EXPECT_FLOAT_EQ(sq.adam().beta2, 0.998001f);
  EXPECT_EQ(plain.adam().lr_scale, 1.f);
  EXPECT_EQ(plain.adam().beta1, 0.9f);
  plain.step();
  sq.step();
  int checked = 0;
  for (size_t k = 0; k < t.model.sh.size(); ++k) {
    const double d0 = double(plain.model().sh[k]) - t.model.sh[k], d1 = double(sq.model().sh[k]) - t.model.sh[k];
    if (std::abs(d0) < 1e-5) continue;  // no gradient (or a tiny one against eps)
    EXPECT_NEAR(d1 / d0, std::sqrt(2.0), 1e-3) << k;
    ++checked;
  }
  EXPECT_GT(checked, 10);
  // sqrt-rates: the rates only.
  cfg.batch_lr = "sqrt-rates";
  Trainer rates(cfg, t.model, {t.views[1], t.views[1]}, 1.f);
  EXPECT_FLOAT_EQ(rates.adam().lr_scale, std::sqrt(2.f));
  EXPECT_EQ(rates.adam().beta1, 0.9f);
  EXPECT_EQ(rates.adam().beta2, 0.999f);
  // One view per step: the rule changes nothing.
  cfg.batch_lr = "sqrt";
  cfg.batch = 1;
  Trainer one(cfg, t.model, {t.views[1]}, 1.f);
  EXPECT_EQ(one.adam().lr_scale, 1.f);
  EXPECT_EQ(one.adam().beta1, 0.9f);
  EXPECT_EQ(one.adam().beta2, 0.999f);
}

TEST(TrainerBatch, SchedulesCountImagesSeenAndEveryViewIsUsedOncePerEpoch) {
  Tiny t(true);
  std::vector<TrainView> views;
  for (int k = 0; k < 2; ++k)
    for (const TrainView& v : t.views) views.push_back(v);  // 6 views: epochs of 3 steps of 2
  TrainConfig cfg = TrainConfig().scaled_to(400);
  cfg.densify_from = 10;
  cfg.densify_every = 20;
  cfg.densify_until = 100;
  cfg.densify_cfg.grad_threshold = 1e-5f;
  cfg.batch = 2;
  auto tap = std::make_unique<GradTap>();
  GradTap& g = *tap;
  Trainer tr(cfg, t.model, views, 1.f, std::move(tap));
  for (int s = 0; s < 30; ++s) tr.step();
  EXPECT_EQ(tr.iteration(), 60);
  EXPECT_EQ(g.densified_at, (std::vector<int>{20, 40, 60}));  // images 20, 40, 60: steps 10, 20, 30
  ASSERT_EQ(g.views.size(), 60u);
  for (size_t e = 0; e + 6 <= g.views.size(); e += 6) {  // each epoch a permutation of the 6 views
    std::vector<int> ep(g.views.begin() + e, g.views.begin() + e + 6);
    std::sort(ep.begin(), ep.end());
    EXPECT_EQ(ep, (std::vector<int>{0, 1, 2, 3, 4, 5}));
  }
  EXPECT_EQ(g.step_views, std::vector<int>(30, 2));
}

TEST(TrainerBatch, ScheduleEndsAtTheSameImageForEveryBatch) {
  // 3DGS densifies at image k when k % every == 0 and from < k < until, and resets opacities when k % reset == 0 and
  // k < until. With until a multiple of both, the step of four views that covers images 97-100 starts before until
  // but covers it: it must neither densify nor reset there (it did both before), as one view per step does not.
  Tiny t(true);
  TrainConfig cfg = TrainConfig().scaled_to(400);
  cfg.densify_from = 10;
  cfg.densify_every = 20;
  cfg.densify_until = 100;
  cfg.opacity_reset_every = 50;
  cfg.densify_cfg.grad_threshold = 1e-5f;
  std::vector<TrainView> views;
  for (int k = 0; k < 4; ++k) views.push_back(t.views[k % t.views.size()]);
  for (int batch : {1, 4}) {
    cfg.batch = batch;
    auto tap = std::make_unique<GradTap>();
    GradTap& g = *tap;
    Trainer tr(cfg, t.model, views, 1.f, std::move(tap));
    auto max_opacity = [&] {
      float m = -1e30f;
      for (float o : tr.model().opacity_logit) m = std::max(m, o);
      return 1.f / (1.f + std::exp(-m));
    };
    float after_reset = 1, after_until = 0;
    while (tr.iteration() < 120) {
      const int prev = tr.iteration();
      tr.step();
      if (prev < 50 && tr.iteration() >= 50) after_reset = max_opacity();  // the reset at image 50
      if (prev < 100 && tr.iteration() >= 100) after_until = max_opacity();
    }
    EXPECT_EQ(g.densified_at, (std::vector<int>{20, 40, 60, 80})) << "batch " << batch;
    EXPECT_LE(after_reset, 0.0101f) << "batch " << batch;  // the reset at 50 happened (the check can see one)
    EXPECT_GT(after_until, 0.0101f) << "batch " << batch;  // none at 100 (a reset leaves every opacity <= 0.01)
  }
}

}  // namespace
}  // namespace hgs::train
