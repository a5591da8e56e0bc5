// Trainer::step: the per-iteration glue between renderer, loss, Adam and densification. Buffers live in the
// trainer and are reused, so a step allocates nothing unless the Gaussian count changed.
#include "train/trainer.h"

#include <algorithm>
#include <chrono>

#include "core/error.h"
#include "model/render_inputs.h"

namespace hgs::train {

Trainer::Trainer(const TrainConfig& cfg, GaussianModel model, std::vector<TrainView> views, float extent)
    : cfg_(cfg), model_(std::move(model)), views_(std::move(views)), extent_(extent), rng_(cfg.seed),
      loss_(cfg.lambda_dssim) {
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
  stats_.reset(model_.n);
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
  out_ = render::RenderOutputs{};
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
  adam_.get("mean").set_lr(cfg_.position_lr(it, extent_));
  const TrainView& v = views_[next_view()];
  const int W = v.cam.width, H = v.cam.height;

  render::GaussianInputs in = render_inputs(model_);
  // 3DGS raises the degree at iterations 1000, 2000, ... before rendering.
  in.sh_degree = std::min(cfg_.sh_degree, cfg_.sh_increase_every > 0 ? it / cfg_.sh_increase_every : cfg_.sh_degree);
  render::RenderSettings rs;
  const float bg = cfg_.white_bg ? 1.f : 0.f;
  rs.background[0] = rs.background[1] = rs.background[2] = bg;
  rs.want_depth = false;
  prepare_inputs(v, in, rs);
  tick(info.times.prepare);
  renderer_.forward(v.cam, in, rs, out_);
  tick(info.times.forward);

  d_rgb_.resize(size_t(W) * H * 3);
  info.loss = loss_(out_.rgb.data(), v.image.px.data(), H, W, d_rgb_.data());
  info.psnr = psnr_from_mse(info.loss.mse);
  render::OutputGrads dout;
  dout.rgb = d_rgb_.data();
  tick(info.times.loss);
  info.loss.total += extra_loss(v, out_, d_rgb_.data(), dout);
  tick(info.times.method_loss);
  renderer_.backward(dout, grads_);
  tick(info.times.backward);
  extra_param_grads(grads_);
  tick(info.times.param_grads);

  // Adam.
  adam_.begin_step();
  adam_.update(adam_.get("mean"), model_.mean.data(), grads_.mean.data(), model_.n);
  adam_.update(adam_.get("log_scale"), model_.log_scale.data(), grads_.log_scale.data(), model_.n);
  adam_.update(adam_.get("quat"), model_.quat.data(), grads_.quat.data(), model_.n);
  adam_.update(adam_.get("opacity"), model_.opacity_logit.data(), grads_.opacity_logit.data(), model_.n);
  adam_.update(adam_.get("sh"), model_.sh.data(), grads_.sh.data(), model_.n);
  method_update();
  tick(info.times.update);

  // Densification (3DGS schedule; statistics are gathered until densify_until).
  if (cfg_.densify && it < cfg_.densify_until) {
    stats_.add(grads_.mean2d.data(), renderer_.radii().data(), model_.n, W, H);
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
  after_step(info);
  tick(info.times.densify);
  info.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return info;
}

}  // namespace hgs::train
