// Trainer::step: the per-iteration glue between renderer, method, loss, Adam and densification. Buffers live in
// the trainer and are reused, so a step allocates nothing unless the Gaussian count changed.
#include "train/trainer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>

#include "core/error.h"
#include "model/render_inputs.h"

namespace hgs::train {

Trainer::~Trainer() = default;

Trainer::Trainer(const TrainConfig& cfg, GaussianModel model, std::vector<TrainView> views, float extent,
                 std::unique_ptr<Method> method)
    : cfg_(cfg), model_(std::move(model)), views_(std::move(views)), extent_(extent), rng_(cfg.seed),
      loss_(cfg.lambda_dssim), method_(method ? std::move(method) : std::make_unique<RgbMethod>()) {
  if (views_.empty()) fail("train: no training views");
  if (model_.n == 0) fail("train: the model has no Gaussians");
  if (cfg_.sh_degree > model_.sh_degree) cfg_.sh_degree = model_.sh_degree;
  model_.validate("train");
  for (auto& v : views_)
    if (v.image.width != v.cam.width || v.image.height != v.cam.height || v.image.channels != 3)
      fail("train: view '{}' image {}x{}x{} does not match its camera {}x{}", v.name, v.image.width, v.image.height,
           v.image.channels, v.cam.width, v.cam.height);
  adam_.add("mean", 3, model_.n, cfg_.lr_position_init * extent_);
  adam_.add("log_scale", 3, model_.n, cfg_.lr_scaling);
  adam_.add("quat", 4, model_.n, cfg_.lr_rotation);
  adam_.add("opacity", 1, model_.n, cfg_.lr_opacity);
  AdamParam& sh = adam_.add("sh", model_.sh_stride() * 3, model_.n, cfg_.lr_sh_rest);
  for (int c = 0; c < 3; ++c) sh.lr[c] = cfg_.lr_sh_dc;
  for (auto [name, f] : std::initializer_list<std::pair<const char*, std::vector<float> GaussianModel::*>>{
           {"mean", &GaussianModel::mean}, {"log_scale", &GaussianModel::log_scale}, {"quat", &GaussianModel::quat},
           {"opacity", &GaussianModel::opacity_logit}, {"sh", &GaussianModel::sh}})
    adam_.get(name).values = [this, f = f] { return ParamValues{&(model_.*f), nullptr}; };
  stats_.reset(model_.n);
  method_->attach(model_, adam_, views_);
  if (const char* e = std::getenv("HGS_INJECT_NAN")) {  // test hook (numerical faults): "<iteration>:<group>"
    const std::string spec = e;
    const size_t colon = spec.find(':');
    char* end = nullptr;
    const long it = colon == std::string::npos ? 0 : std::strtol(spec.c_str(), &end, 10);
    inject_group_ = colon == std::string::npos ? "" : spec.substr(colon + 1);
    const bool known = inject_group_ == "loss" || inject_group_ == "mean" || inject_group_ == "log_scale" ||
                       inject_group_ == "quat" || inject_group_ == "opacity" || inject_group_ == "sh";
    if (it <= 0 || end != spec.c_str() + colon || !known)
      fail("HGS_INJECT_NAN: expected <iteration>:<loss|mean|log_scale|quat|opacity|sh>, got '{}'", spec);
    inject_iter_ = int(it);
  }
}

void Trainer::check_finite(int it) const {
  for (const LossTerm& t : objective_.terms())
    if (!std::isfinite(t.value))
      fail("train: iteration {}: the '{}' loss is {} (non-finite); training stopped", it, t.name, t.value);
  if (!adam_.first_nonfinite()) return;
  std::string groups;  // every group that saw one, in registration order (a NaN spreads through the chain rule)
  for (const AdamParam& p : adam_.params)
    if (p.nonfinite > 0) groups += fmt::format("{}'{}' ({} values)", groups.empty() ? "" : ", ", p.name, p.nonfinite);
  fail("train: iteration {}: non-finite gradient (NaN/Inf) in parameter group {}; training stopped", it, groups);
}

int Trainer::active_sh_degree() const {
  int d = cfg_.sh_increase_every > 0 ? it_ / cfg_.sh_increase_every : cfg_.sh_degree;
  return std::min(d, cfg_.sh_degree);
}

int Trainer::next_view() {
  if (order_pos_ >= order_.size()) {
    order_.resize(views_.size());
    for (size_t i = 0; i < order_.size(); ++i) order_[i] = int(i);
    std::shuffle(order_.begin(), order_.end(), rng_);
    order_pos_ = 0;
  }
  return order_[order_pos_++];
}

void Trainer::release_step_buffers() {
  renderer_.release();
  grads_ = render::GaussianGrads{};
  pgrads_ = render::ProjectedGrads{};
  out_ = render::RenderOutputs{};
  method_->release();
}

StepInfo Trainer::step() {
  auto t0 = std::chrono::steady_clock::now();
  StepInfo info;
  auto tick = [&, tp = t0](double& part) mutable {  // adds the time since the previous tick to `part`
    const auto now = std::chrono::steady_clock::now();
    part += std::chrono::duration<double, std::milli>(now - tp).count();
    tp = now;
  };
  if (model_.n == 0) fail("train: every Gaussian was pruned by iteration {}", it_);
  const int it = ++it_;  // 1-based, as in 3DGS
  adam_.clear_nonfinite();
  adam_.get("mean").set_lr(cfg_.position_lr(it, extent_));
  const int vi = next_view();
  const TrainView& v = views_[vi];
  const int W = v.cam.width, H = v.cam.height;

  render::GaussianInputs in = render_inputs(model_);
  // 3DGS raises the degree at iterations 1000, 2000, ... before rendering.
  in.sh_degree = std::min(cfg_.sh_degree, cfg_.sh_increase_every > 0 ? it / cfg_.sh_increase_every : cfg_.sh_degree);
  render::RenderSettings rs;
  const float bg = cfg_.white_bg ? 1.f : 0.f;
  rs.background[0] = rs.background[1] = rs.background[2] = bg;
  rs.want_depth = false;
  render::OutputGrads dout;
  objective_.clear();
  StepContext c;
  c.iteration = it;
  c.view_index = vi;
  c.view = &v;
  c.model = &model_;
  c.optim = &adam_;
  c.rng = &rng_;
  c.inputs = &in;
  c.settings = &rs;
  c.dout = &dout;
  c.grads = &grads_;
  c.objective = &objective_;
  c.sh_degree = in.sh_degree;
  render::Channels channels;
  c.channels = &channels;
  c.pgrads = &pgrads_;
  renderer_.preprocess(v.cam, in);  // projection, SH of the visible Gaussians, tile binning
  const render::ProjectedView<float> projected = renderer_.projected();
  c.projected = &projected;
  tick(info.times.forward);
  method_->prepare(c);  // may build extra channels from the projected colours
  tick(info.times.prepare);
  renderer_.composite(channels, rs, out_);
  c.out = &out_;
  tick(info.times.forward);

  d_rgb_.resize(size_t(W) * H * 3);
  info.loss = loss_(out_.rgb.data(), v.image.px.data(), H, W, d_rgb_.data());
  info.psnr = psnr_from_mse(info.loss.mse);
  const float w_rgb = method_->rgb_weight();
  if (w_rgb != 1.f)
    for (float& g : d_rgb_) g *= w_rgb;
  if (it == inject_iter_ && inject_group_ == "loss") info.loss.total = d_rgb_[0] = std::nanf("");
  objective_.add("rgb", w_rgb, info.loss.total);
  dout.rgb = d_rgb_.data();
  c.d_rgb = d_rgb_.data();
  tick(info.times.loss);
  method_->losses(c);
  tick(info.times.method_loss);
  renderer_.composite_backward(dout, pgrads_);
  tick(info.times.backward);
  method_->backward(c);  // may add to pgrads_.colors (its channels' colour gradient)
  tick(info.times.param_grads);
  renderer_.preprocess_backward(pgrads_, grads_);
  tick(info.times.backward);

  if (it == inject_iter_ && inject_group_ != "loss") {
    std::vector<float>* g = inject_group_ == "mean" ? &grads_.mean : inject_group_ == "log_scale" ? &grads_.log_scale
                            : inject_group_ == "quat" ? &grads_.quat : inject_group_ == "opacity" ? &grads_.opacity_logit
                                                                                                   : &grads_.sh;
    (*g)[g->size() / 2] = std::nanf("");
  }

  // Adam.
  adam_.update(adam_.get("mean"), model_.mean.data(), grads_.mean.data(), model_.n);
  adam_.update(adam_.get("log_scale"), model_.log_scale.data(), grads_.log_scale.data(), model_.n);
  adam_.update(adam_.get("quat"), model_.quat.data(), grads_.quat.data(), model_.n);
  adam_.update(adam_.get("opacity"), model_.opacity_logit.data(), grads_.opacity_logit.data(), model_.n);
  adam_.update(adam_.get("sh"), model_.sh.data(), grads_.sh.data(), model_.n);
  method_->update(c);
  // Numerical faults: every loss term finite and every gradient value the optimiser saw this step (the method's
  // parameters too, some updated during losses/backward) finite; else stop before densification and before
  // anything is saved (hgs train keeps its last checkpoint).
  check_finite(it);
  adam_.clear_nonfinite();
  tick(info.times.update);
  info.terms = objective_.terms();
  info.total = objective_.total();

  // Densification (3DGS schedule; statistics are gathered until densify_until).
  if (cfg_.densify && it < cfg_.densify_until) {
    stats_.add(pgrads_.mean2d.data(), renderer_.radii().data(), model_.n, W, H);
    if (it > cfg_.densify_from && it % cfg_.densify_every == 0) {
      release_step_buffers();
      float screen = it > cfg_.opacity_reset_every ? cfg_.screen_limit : 0.f;
      info.densify = densify_and_prune(model_, adam_, stats_, cfg_.densify_cfg, extent_, screen, rng_);
      info.densified = true;
    }
    if (it % cfg_.opacity_reset_every == 0 || (cfg_.white_bg && it == cfg_.densify_from))
      reset_opacity(model_, adam_, 0.01f);
  }
  info.num_gaussians = model_.n;
  method_->after_step(c, info.densified);
  tick(info.times.densify);
  info.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return info;
}

}  // namespace hgs::train
