// Numerical faults (docs/reliability.md): Adam counts the non-finite gradient values of every update (flat,
// per-column rates, row-sparse with float32 or bfloat16 moments), and Trainer::step stops with an hgs::Error
// naming the iteration and the parameter group or loss term, for the 3DGS groups and for parameters a Method
// registers itself (poisoned through the Method interface). End to end through `hgs train`:
// test_crash_safety.cpp (HGS_INJECT_NAN).
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include "core/error.h"
#include "train/trainer.h"

namespace hgs::train {
namespace {

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

TEST(AdamNonFinite, FlatAndPerColumnUpdatesCountBadGradients) {
  for (bool per_column : {false, true}) {
    Adam a;
    AdamParam& p = a.add("x", 4, 50, 0.01f);
    if (per_column) p.lr[0] = 0.1f;  // different rates: the row-by-row loop
    std::vector<float> x(200, 1.f), g(200, 0.5f);
    a.update(p, x.data(), g.data(), 50);
    EXPECT_EQ(p.nonfinite, 0);
    EXPECT_EQ(a.first_nonfinite(), nullptr);
    g[17] = kNan;
    g[150] = -kInf;
    g[199] = kInf;
    g[3] = std::numeric_limits<float>::max();  // large but finite
    g[4] = std::numeric_limits<float>::denorm_min();
    a.update(p, x.data(), g.data(), 50);
    EXPECT_EQ(p.nonfinite, 3) << per_column;
    EXPECT_EQ(a.first_nonfinite(), &p);
    a.clear_nonfinite();
    EXPECT_EQ(p.nonfinite, 0);
  }
}

TEST(AdamNonFinite, RowUpdatesCountBadGradients) {
  for (bool bf16 : {false, true}) {
    Adam a;
    a.add("first", 1, 10, 0.01f);
    AdamParam& p = a.add("f", 40, 100, 0.01f, bf16);  // 40 columns: the AVX2 bfloat16 path and its scalar tail
    std::vector<float> x(4000, 0.f);
    a.update_rows(p, x.data(), 100, [&](long i, float* g) {
      for (int c = 0; c < 40; ++c) g[c] = 0.01f * float(c - 20);
      if (i == 7) g[3] = kNan;    // in a 16-wide block
      if (i == 60) g[39] = kInf;  // in the tail
      return i % 2 == 0 || i == 7;
    });
    EXPECT_EQ(p.nonfinite, 2) << bf16;
    EXPECT_EQ(a.first_nonfinite(), &p);
    a.clear_nonfinite();
    // A row without a gradient is not looked at.
    a.update_rows(p, x.data(), 100, [&](long /*i*/, float* g) {
      g[0] = kNan;
      return false;
    });
    EXPECT_EQ(p.nonfinite, 0);
    std::vector<float> g(40, kNan);
    a.update_row(p, x.data(), 5, g.data());
    EXPECT_EQ(p.nonfinite, 40);
  }
}

// One 24x16 view of a flat colour and 30 random Gaussians in front of it.
struct Problem {
  GaussianModel model;
  std::vector<TrainView> views;
  Problem() {
    model.sh_degree = 0;
    model.resize(30);
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> U(-1, 1);
    for (int i = 0; i < model.n; ++i) {
      model.mean[i * 3] = U(rng);
      model.mean[i * 3 + 1] = 0.6f * U(rng);
      model.mean[i * 3 + 2] = 3 + U(rng);
      for (int a = 0; a < 3; ++a) model.log_scale[i * 3 + a] = std::log(0.2f);
      model.quat[i * 4] = 1;
      model.opacity_logit[i] = U(rng);
      for (int c = 0; c < 3; ++c) model.sh[i * 3 + c] = U(rng);
    }
    TrainView v;
    v.name = "v";
    v.cam.width = 24;
    v.cam.height = 16;
    v.cam.fx = v.cam.fy = 20;
    v.cam.cx = 12;
    v.cam.cy = 8;
    v.image = Image(24, 16, 3);
    for (size_t k = 0; k < v.image.px.size(); ++k) v.image.px[k] = 0.3f + 0.2f * float(k % 3);
    views.push_back(v);
  }
  TrainConfig config() const {
    TrainConfig c = TrainConfig().scaled_to(100);
    c.densify = false;
    c.sh_degree = 0;
    return c;
  }
};

// A method with its own array parameter, poisoned at one iteration in one of its parts.
class Poison final : public Method {
 public:
  enum Where { kNone, kLossTerm, kArrayGradient, kColourGradient };
  Poison(Where w, int at) : where_(w), at_(at) {}
  std::string name() const override { return "poison"; }
  void attach(GaussianModel&, Adam& optim, const std::vector<TrainView>&) override {
    optim.add_array("poison_logits", 1, 4, 0.01f).values = [this] { return ParamValues{&logits_, nullptr}; };
  }
  void losses(const ViewStep& v, const LossIO& io) override {
    io.objective.add("extra", 0.5f, where_ == kLossTerm && v.iteration == at_ ? double(kNan) : 0.1);
  }
  void backward(const ViewStep& v, const BackwardIO& io) override {
    if (where_ == kColourGradient && v.iteration == at_)  // flows into SH
      std::fill(io.grads.colors.begin(), io.grads.colors.end(), kInf);
    iteration_ = v.iteration;
  }
  void update(const UpdateIO& io) override {
    std::vector<float> g(4, 0.1f);
    if (where_ == kArrayGradient && iteration_ == at_) g[2] = kNan;
    io.optim.update(io.optim.get("poison_logits"), logits_.data(), g.data(), 4);
  }

 private:
  Where where_;
  int at_;
  int iteration_ = 0;
  std::vector<float> logits_ = std::vector<float>(4, 0.f);
};

std::string step_error(Poison::Where w, int at, int* stopped_at) {
  Problem p;
  Trainer t(p.config(), p.model, p.views, 1.f, std::make_unique<Poison>(w, at));
  for (int i = 0; i < 20; ++i) {
    try {
      t.step();
    } catch (const Error& e) {
      *stopped_at = t.iteration();
      return e.what();
    }
  }
  *stopped_at = t.iteration();
  return "";
}

TEST(TrainerNonFinite, StopsNamingTheIterationAndTheGroup) {
  int it = 0;
  EXPECT_EQ(step_error(Poison::kNone, 0, &it), "");
  EXPECT_EQ(it, 20);
  std::string e = step_error(Poison::kArrayGradient, 7, &it);
  EXPECT_EQ(it, 7);
  EXPECT_NE(e.find("iteration 7: non-finite gradient (NaN/Inf) in parameter group 'poison_logits' (1 values);"),
            std::string::npos)
      << e;
  e = step_error(Poison::kLossTerm, 4, &it);
  EXPECT_EQ(it, 4);
  EXPECT_NE(e.find("iteration 4: the 'extra' loss is nan"), std::string::npos) << e;
  // An infinite projected colour gradient reaches the SH coefficients, and the positions too (the view
  // direction's zero derivative times infinity): every group that saw one is named.
  e = step_error(Poison::kColourGradient, 9, &it);
  EXPECT_EQ(it, 9);
  EXPECT_NE(e.find("iteration 9: non-finite gradient (NaN/Inf) in parameter group "), std::string::npos) << e;
  EXPECT_NE(e.find("'sh' ("), std::string::npos) << e;
  EXPECT_EQ(e.find("'poison_logits'"), std::string::npos) << e;
  EXPECT_EQ(e.find('\n'), std::string::npos);
}

}  // namespace
}  // namespace hgs::train
