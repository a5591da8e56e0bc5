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
                 std::unique_ptr<Method> method, Reducer* reducer)
    : cfg_(cfg), model_(std::move(model)), views_(std::move(views)), extent_(extent), rng_(cfg.seed),
      loss_(cfg.lambda_dssim), method_(method ? std::move(method) : std::make_unique<RgbMethod>()) {
  reducer_ = reducer ? reducer : &local_reducer_;
  if (views_.empty()) fail("train: no training views");
  if (cfg_.batch < 1) fail("train: the batch must be at least 1 view, got {}", cfg_.batch);
  if (!is_batch_lr_rule(cfg_.batch_lr))
    fail("train: unknown batch learning-rate rule '{}' (none, sqrt or sqrt-rates)", cfg_.batch_lr);
  if (cfg_.batch_lr != "none" && step_views() > 1) {  // config.h: the batch rules
    const int G = step_views();
    adam_.lr_scale = float(std::sqrt(double(G)));
    if (cfg_.batch_lr == "sqrt") {
      adam_.beta1 = float(std::pow(double(adam_.beta1), G));
      adam_.beta2 = float(std::pow(double(adam_.beta2), G));
    }
  }
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
  view_grads_ = render::GaussianGrads{};
  pgrads_ = render::ProjectedGrads{};
  out_ = render::RenderOutputs{};
  method_->release();
}

int Trainer::step_views() const { return cfg_.batch * reducer_->size(); }

namespace {

// Whether a multiple of `every` lies in (prev, cur]: an event of a schedule counted in images seen happens in the
// step that covers it (for one view per step: cur % every == 0).
bool crosses(int prev, int cur, int every) { return every > 0 && cur / every > prev / every; }

// The seed of one view's random numbers (method sampling): from the run's seed, the step's first image and the
// view's place in the global batch, so the split of a batch over ranks does not change them.
uint64_t view_seed(uint64_t seed, int iteration, int global_slot) {
  uint64_t x = seed * 0x9E3779B97F4A7C15ULL + uint64_t(iteration) * 0xBF58476D1CE4E5B9ULL + uint64_t(global_slot);
  x ^= x >> 31;
  x *= 0x94D049BB133111EBULL;
  return x ^ (x >> 29);
}

template <class F>
void each_grad(render::GaussianGrads& g, F&& f) {  // the 3DGS parameter gradients, in pack order
  for (auto* v : {&g.mean, &g.log_scale, &g.quat, &g.opacity_logit, &g.sh}) f(*v);
}

}  // namespace

void Trainer::reduce_and_scale(float grad_scale) {
  Reducer& r = *reducer_;
  if (r.size() > 1) {
    // One buffer: every 3DGS gradient and the statistics' sums (norms, counts); the radii go by maximum.
    size_t total = 2 * size_t(step_stats_.n);
    each_grad(grads_, [&](std::vector<float>& v) { total += v.size(); });
    pack_.resize(total);
    size_t o = 0;
    each_grad(grads_, [&](std::vector<float>& v) {
      std::copy(v.begin(), v.end(), pack_.begin() + o);
      o += v.size();
    });
    std::copy(step_stats_.v.begin(), step_stats_.v.begin() + 2 * size_t(step_stats_.n), pack_.begin() + o);
    r.sum(pack_.data(), pack_.size());
    o = 0;
    each_grad(grads_, [&](std::vector<float>& v) {
      std::copy(pack_.begin() + o, pack_.begin() + o + v.size(), v.begin());
      o += v.size();
    });
    std::copy(pack_.begin() + o, pack_.end(), step_stats_.v.begin());
    r.max(step_stats_.max_radius(), size_t(step_stats_.n));
  }
  if (grad_scale != 1.f)
    each_grad(grads_, [&](std::vector<float>& v) {
#pragma omp parallel for simd schedule(static)
      for (size_t k = 0; k < v.size(); ++k) v[k] *= grad_scale;
    });
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
  const int B = cfg_.batch, G = step_views(), prev = it_;
  const int it = prev + 1;  // 1-based, as in 3DGS: the step's first image
  it_ += G;
  adam_.clear_nonfinite();
  adam_.get("mean").set_lr(cfg_.position_lr(it, extent_));
  // The global batch: G views of the shared order (every rank draws all of them); this rank takes its B.
  std::vector<int> batch_views(G);
  for (int& vi : batch_views) vi = next_view();

  render::GaussianInputs in = render_inputs(model_);
  // 3DGS raises the degree at iterations 1000, 2000, ... before rendering.
  in.sh_degree = std::min(cfg_.sh_degree, cfg_.sh_increase_every > 0 ? it / cfg_.sh_increase_every : cfg_.sh_degree);
  const float bg = cfg_.white_bg ? 1.f : 0.f;
  StepContext c;
  c.iteration = it;
  c.model = &model_;
  c.optim = &adam_;
  c.inputs = &in;
  c.grads = &grads_;
  c.objective = &objective_;
  c.sh_degree = in.sh_degree;
  c.pgrads = &pgrads_;
  c.step_views = G;
  c.grad_scale = G > 1 ? 1.f / float(G) : 1.f;
  c.reducer = reducer_;
  if (!(cfg_.densify && it < cfg_.densify_until) && step_stats_.n > 0) step_stats_ = StepStats{};  // not gathering
  std::vector<LossTerm> terms;  // summed over this process's views, then the mean
  double mse = 0;
  for (int b = 0; b < B; ++b) {
    const int gs = reducer_->rank() * B + b, vi = batch_views[gs];
    const TrainView& v = views_[vi];
    const int W = v.cam.width, H = v.cam.height;
    // One view per step draws from the trainer's own stream (as before batches existed: runs of earlier
    // versions reproduce bit for bit); with several, each view has its own stream, because every rank must keep
    // the shared one (view order, densification) in step with the others.
    std::mt19937_64 view_rng(G > 1 ? view_seed(cfg_.seed, it, gs) : 0);
    render::RenderSettings rs;
    rs.background[0] = rs.background[1] = rs.background[2] = bg;
    rs.want_depth = false;
    render::OutputGrads dout;
    objective_.clear();
    c.view_index = vi;
    c.view = &v;
    c.slot = b;
    c.global_slot = gs;
    c.rng = G > 1 ? &view_rng : &rng_;
    c.settings = &rs;
    c.dout = &dout;
    render::Channels channels;
    c.channels = &channels;
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
    const LossValues lv = loss_(out_.rgb.data(), v.image.px.data(), H, W, d_rgb_.data());
    LossValues vl = lv;
    const float w_rgb = method_->rgb_weight();
    if (w_rgb != 1.f)
      for (float& g : d_rgb_) g *= w_rgb;
    if (it == inject_iter_ && inject_group_ == "loss") vl.total = d_rgb_[0] = std::nanf("");
    objective_.add("rgb", w_rgb, vl.total);
    dout.rgb = d_rgb_.data();
    c.d_rgb = d_rgb_.data();
    tick(info.times.loss);
    method_->losses(c);
    tick(info.times.method_loss);
    renderer_.composite_backward(dout, pgrads_);
    tick(info.times.backward);
    method_->backward(c);  // may add to pgrads_.colors (its channels' colour gradient)
    tick(info.times.param_grads);
    renderer_.preprocess_backward(pgrads_, b == 0 ? grads_ : view_grads_);
    if (b > 0) {  // the step's sum, in view order
      std::vector<std::vector<float>*> sum, add;
      each_grad(grads_, [&](std::vector<float>& x) { sum.push_back(&x); });
      each_grad(view_grads_, [&](std::vector<float>& x) { add.push_back(&x); });
      for (size_t k = 0; k < sum.size(); ++k) {
        float* s = sum[k]->data();
        const float* a = add[k]->data();
#pragma omp parallel for simd schedule(static)
        for (size_t e = 0; e < sum[k]->size(); ++e) s[e] += a[e];
      }
    }
    if (cfg_.densify && it < cfg_.densify_until)
      step_stats_.add_view(pgrads_.mean2d.data(), renderer_.radii().data(), model_.n, W, H, b == 0);
    tick(info.times.backward);

    if (b == 0) {
      info.loss = lv;
      terms = objective_.terms();
    } else {
      info.loss.total += lv.total;
      info.loss.l1 += lv.l1;
      info.loss.ssim += lv.ssim;
      info.loss.mse += lv.mse;
      for (size_t k = 0; k < terms.size() && k < objective_.terms().size(); ++k)
        terms[k].value += objective_.terms()[k].value;
    }
  }
  if (B > 1) {
    info.loss.total /= B;
    info.loss.l1 /= B;
    info.loss.ssim /= B;
    info.loss.mse /= B;
    for (LossTerm& t : terms) t.value /= B;
  }
  info.psnr = psnr_from_mse(info.loss.mse);
  objective_.clear();
  for (const LossTerm& t : terms) objective_.add(t.name, t.weight, t.value);

  if (it == inject_iter_ && inject_group_ != "loss") {
    std::vector<float>* g = inject_group_ == "mean" ? &grads_.mean : inject_group_ == "log_scale" ? &grads_.log_scale
                            : inject_group_ == "quat" ? &grads_.quat : inject_group_ == "opacity" ? &grads_.opacity_logit
                                                                                                   : &grads_.sh;
    (*g)[g->size() / 2] = std::nanf("");
  }

  // The global batch: the ranks' sums added in rank order, then the mean.
  const double comm_ms0 = reducer_->stats.ms;
  reduce_and_scale(c.grad_scale);
  method_->reduce(c);
  info.times.reduce = reducer_->stats.ms - comm_ms0;
  tick(info.times.update);
  info.times.update -= info.times.reduce;

  // Adam.
  adam_.update(adam_.get("mean"), model_.mean.data(), grads_.mean.data(), model_.n);
  adam_.update(adam_.get("log_scale"), model_.log_scale.data(), grads_.log_scale.data(), model_.n);
  adam_.update(adam_.get("quat"), model_.quat.data(), grads_.quat.data(), model_.n);
  adam_.update(adam_.get("opacity"), model_.opacity_logit.data(), grads_.opacity_logit.data(), model_.n);
  adam_.update(adam_.get("sh"), model_.sh.data(), grads_.sh.data(), model_.n);
  method_->update(c);
  // Numerical faults: every loss term finite and every gradient value the optimiser saw this step (the method's
  // parameters too) finite; else stop before densification and before anything is saved (hgs train keeps its
  // last checkpoint).
  check_finite(it);
  adam_.clear_nonfinite();
  tick(info.times.update);
  info.terms = objective_.terms();
  info.total = objective_.total();

  // Densification (3DGS schedule in images seen; statistics are gathered until densify_until).
  if (cfg_.densify && it < cfg_.densify_until) {
    stats_.add(step_stats_);
    if (it_ > cfg_.densify_from && crosses(prev, it_, cfg_.densify_every)) {
      release_step_buffers();
      float screen = it_ > cfg_.opacity_reset_every ? cfg_.screen_limit : 0.f;
      info.densify = densify_and_prune(model_, adam_, stats_, cfg_.densify_cfg, extent_, screen, rng_);
      info.densified = true;
    }
    if (crosses(prev, it_, cfg_.opacity_reset_every) ||
        (cfg_.white_bg && prev < cfg_.densify_from && it_ >= cfg_.densify_from))
      reset_opacity(model_, adam_, 0.01f);
  }
  info.num_gaussians = model_.n;
  method_->after_step(c, info.densified);
  tick(info.times.densify);
  info.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return info;
}

}  // namespace hgs::train
