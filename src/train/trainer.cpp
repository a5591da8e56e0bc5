// Trainer::step: the per-iteration glue between renderer, method, loss, Adam and densification. Buffers live in
// the trainer and are reused, so a step allocates nothing unless the Gaussian count changed.
#include "train/trainer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <limits>

#include "core/error.h"
#include "model/render_inputs.h"
#include "train/gaussian_params.h"

namespace hgs::train {

Trainer::~Trainer() = default;

Trainer::Trainer(const TrainConfig& cfg, GaussianModel model, std::vector<TrainView> views, float extent,
                 std::unique_ptr<Method> method, Reducer* reducer)
    : cfg_(cfg),
      model_(std::move(model)),
      views_(std::move(views)),
      extent_(extent),
      rng_(cfg.seed),
      loss_(cfg.lambda_dssim),
      method_(method ? std::move(method) : std::make_unique<RgbMethod>()) {
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
  register_gaussian_params();
  stats_.reset(model_.n);
  method_->attach(model_, adam_, views_);
  parse_inject_nan();
}

void Trainer::register_gaussian_params() {
  for (const GaussianParam& p : kGaussianParams) {
    AdamParam& a = adam_.add(p.name, p.cols(model_), model_.n, cfg_.*p.lr * (p.times_extent ? extent_ : 1.f));
    if (p.lr_dc)
      for (int c = 0; c < 3; ++c) a.lr[c] = cfg_.*p.lr_dc;
    a.values = [this, value = p.value] { return ParamValues{&(model_.*value), nullptr}; };
  }
}

void Trainer::parse_inject_nan() {
  const char* e = std::getenv("HGS_INJECT_NAN");  // test hook (numerical faults): "<iteration>:<group>"
  if (!e) return;
  const std::string spec = e;
  const size_t colon = spec.find(':');
  char* end = nullptr;
  const long it = colon == std::string::npos ? 0 : std::strtol(spec.c_str(), &end, 10);
  inject_group_ = colon == std::string::npos ? "" : spec.substr(colon + 1);
  const bool known = inject_group_ == "loss" || find_gaussian_param(inject_group_);
  if (it <= 0 || end != spec.c_str() + colon || !known) {
    std::string groups = "loss";
    for (const GaussianParam& p : kGaussianParams) groups += fmt::format("|{}", p.name);
    fail("HGS_INJECT_NAN: expected <iteration>:<{}>, got '{}'", groups, spec);
  }
  inject_iter_ = int(it);
}

void Trainer::inject_gradient_nan(int it) {
  if (it != inject_iter_ || inject_group_ == "loss") return;
  std::vector<float>& g = grads_.*(find_gaussian_param(inject_group_)->grad);
  g[g.size() / 2] = std::nanf("");
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

int Trainer::sh_degree_at(int iteration) const {
  const int d = cfg_.sh_increase_every > 0 ? iteration / cfg_.sh_increase_every : cfg_.sh_degree;
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
// The last image in (prev, cur] that is a multiple of `every` (0 = none, or every <= 0): the image a schedule's
// event of this step belongs to.
int event_image(int prev, int cur, int every) { return crosses(prev, cur, every) ? cur / every * every : 0; }

// The seed of one view's random numbers (method sampling): from the run's seed, the step's first image and the
// view's place in the global batch, so the split of a batch over ranks does not change them.
uint64_t view_seed(uint64_t seed, int iteration, int global_slot) {
  uint64_t x = seed * 0x9E3779B97F4A7C15ULL + uint64_t(iteration) * 0xBF58476D1CE4E5B9ULL + uint64_t(global_slot);
  x ^= x >> 31;
  x *= 0x94D049BB133111EBULL;
  return x ^ (x >> 29);
}

template <class F>
void each_grad(render::GaussianGrads& g, F&& f) {  // the 3DGS parameter gradients, in table order
  for (const GaussianParam& p : kGaussianParams) f(g.*p.grad);
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

// Wall time of a step's parts: tick(part) adds the time since the previous tick to `part`.
class Trainer::PartClock {
 public:
  using clock = std::chrono::steady_clock;
  explicit PartClock(clock::time_point start) : last_(start) {}
  void tick(double& part) {
    const clock::time_point now = clock::now();
    part += std::chrono::duration<double, std::milli>(now - last_).count();
    last_ = now;
  }

 private:
  clock::time_point last_;
};

// Which views a step takes and how it counts them.
struct Trainer::StepPlan {
  int prev = 0;               // images seen before the step
  int iteration = 0;          // 1-based, as in 3DGS: the step's first image
  int local_views = 1;        // B: this process's views
  int step_views = 1;         // G: views of the global batch
  float grad_scale = 1;       // 1 / G
  bool gather_stats = false;  // densification statistics are gathered this step
  std::vector<int> views;     // [G] view indices of the global batch (every rank draws all of them)
};

// This process's per-view results, summed over its views.
struct Trainer::ViewSums {
  LossValues loss;
  std::vector<LossTerm> terms;
};

Trainer::StepPlan Trainer::plan_step() {
  StepPlan p;
  p.local_views = cfg_.batch;
  p.step_views = step_views();
  p.prev = it_;
  p.iteration = it_ + 1;
  p.grad_scale = p.step_views > 1 ? 1.f / float(p.step_views) : 1.f;
  p.gather_stats = cfg_.densify && (p.iteration < cfg_.densify_until || cfg_.late_prune > 0);
  p.views.resize(p.step_views);
  for (int& vi : p.views) vi = next_view();
  return p;
}

StepInfo Trainer::step() {
  const auto t0 = std::chrono::steady_clock::now();
  PartClock clock(t0);
  StepInfo info;
  if (model_.n == 0) fail("train: every Gaussian was pruned by iteration {}", it_);
  adam_.clear_nonfinite();
  const StepPlan plan = plan_step();
  it_ += plan.step_views;
  adam_.get("mean").set_lr(cfg_.position_lr(plan.iteration, extent_));
  render::GaussianInputs in = render_inputs(model_);
  in.sh_degree = sh_degree_at(plan.iteration);
  if (!plan.gather_stats && step_stats_.n > 0) step_stats_ = StepStats{};
  ViewSums sums;
  for (int b = 0; b < plan.local_views; ++b) train_view(plan, b, in, sums, clock, info.times);
  average_views(sums, info);
  inject_gradient_nan(plan.iteration);
  reduce_step(plan, clock, info.times);
  update_parameters(plan, clock, info.times, info);
  densify_step(plan, info);
  info.num_gaussians = model_.n;
  method_->after_step({plan.iteration, it_, info.densified, model_});
  clock.tick(info.times.densify);
  info.ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  return info;
}

// One view of the step: render, losses, backward; its 3DGS gradients added to the step's sum.
void Trainer::train_view(const StepPlan& plan, int slot, const render::GaussianInputs& in, ViewSums& sums,
                         PartClock& clock, StepTimes& times) {
  const int gs = reducer_->rank() * plan.local_views + slot, vi = plan.views[gs];
  const TrainView& v = views_[vi];
  // One view per step draws from the trainer's own stream; with several, each view has its own stream, because
  // every rank must keep the shared one (view order, densification) in step with the others.
  std::mt19937_64 view_rng(plan.step_views > 1 ? view_seed(cfg_.seed, plan.iteration, gs) : 0);
  const ViewStep vs{plan.iteration, vi, v, slot, gs, plan.step_views > 1 ? view_rng : rng_, model_};
  objective_.clear();
  render_view(vs, in, cfg_.white_bg ? 1.f : 0.f, clock, times);

  const int W = v.cam.width, H = v.cam.height;
  d_rgb_.resize(size_t(W) * H * 3);
  const LossValues lv = loss_(out_.rgb.data(), v.image.px.data(), H, W, d_rgb_.data());
  LossValues vl = lv;
  const float w_rgb = method_->rgb_weight();
  if (w_rgb != 1.f)
    for (float& g : d_rgb_) g *= w_rgb;
  if (plan.iteration == inject_iter_ && inject_group_ == "loss") vl.total = d_rgb_[0] = std::nanf("");
  objective_.add("rgb", w_rgb, vl.total);
  render::OutputGrads dout;
  dout.rgb = d_rgb_.data();
  clock.tick(times.loss);
  method_->losses(vs, {out_, d_rgb_.data(), dout, objective_});
  clock.tick(times.method_loss);

  renderer_.composite_backward(dout, pgrads_);
  clock.tick(times.backward);
  method_->backward(vs, {renderer_.projected(), pgrads_});  // may add to pgrads_.colors (its channels' colour)
  clock.tick(times.param_grads);
  renderer_.preprocess_backward(pgrads_, slot == 0 ? grads_ : view_grads_);
  add_view_gradients(slot);
  if (plan.gather_stats)
    step_stats_.add_view(pgrads_.mean2d.data(), renderer_.radii().data(), model_.n, W, H, slot == 0);
  clock.tick(times.backward);

  if (slot == 0) {
    sums.loss = lv;
    sums.terms = objective_.terms();
  } else {
    sums.loss.total += lv.total;
    sums.loss.l1 += lv.l1;
    sums.loss.ssim += lv.ssim;
    sums.loss.mse += lv.mse;
    for (size_t k = 0; k < sums.terms.size() && k < objective_.terms().size(); ++k)
      sums.terms[k].value += objective_.terms()[k].value;
  }
}

// The renderer's two phases around the method's prepare: out_ holds the view's RGB and the method's channels.
void Trainer::render_view(const ViewStep& vs, const render::GaussianInputs& in, float background, PartClock& clock,
                          StepTimes& times) {
  render::RenderSettings rs;
  rs.background[0] = rs.background[1] = rs.background[2] = background;
  rs.want_depth = false;
  render::Channels channels;
  renderer_.preprocess(vs.view.cam, in);  // projection, SH of the visible Gaussians, tile binning
  clock.tick(times.forward);
  method_->prepare(vs, {renderer_.projected(), channels, rs});  // may build extra channels from the colours
  clock.tick(times.prepare);
  renderer_.composite(channels, rs, out_);
  clock.tick(times.forward);
}

// grads_ += view_grads_ for the second and later views of a step (the step's sum, in view order).
void Trainer::add_view_gradients(int slot) {
  if (slot == 0) return;
  for (const GaussianParam& p : kGaussianParams) {
    std::vector<float>& sum = grads_.*p.grad;
    const std::vector<float>& add = view_grads_.*p.grad;
    float* s = sum.data();
    const float* a = add.data();
#pragma omp parallel for simd schedule(static)
    for (size_t e = 0; e < sum.size(); ++e) s[e] += a[e];
  }
}

// The step's loss values and terms: the mean over this process's views.
void Trainer::average_views(const ViewSums& sums, StepInfo& info) {
  const int B = cfg_.batch;
  info.loss = sums.loss;
  std::vector<LossTerm> terms = sums.terms;
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
}

// The global batch: the ranks' sums added in rank order, then the mean.
void Trainer::reduce_step(const StepPlan& plan, PartClock& clock, StepTimes& times) {
  const double comm_ms0 = reducer_->stats.ms;
  reduce_and_scale(plan.grad_scale);
  method_->reduce(*reducer_);
  times.reduce = reducer_->stats.ms - comm_ms0;
  clock.tick(times.update);
  times.update -= times.reduce;
}

// Adam on the 3DGS parameters, then the method's updates; stops on a non-finite loss or gradient.
void Trainer::update_parameters(const StepPlan& plan, PartClock& clock, StepTimes& times, StepInfo& info) {
  for (const GaussianParam& p : kGaussianParams)
    adam_.update(adam_.get(p.name), (model_.*p.value).data(), (grads_.*p.grad).data(), model_.n);
  method_->update({plan.iteration, plan.step_views, plan.grad_scale, model_, adam_, grads_});
  // Numerical faults: every loss term finite and every gradient value the optimiser saw this step (the method's
  // parameters too) finite; else stop before densification and before anything is saved (hgs train keeps its
  // last checkpoint).
  check_finite(plan.iteration);
  adam_.clear_nonfinite();
  clock.tick(times.update);
  info.terms = objective_.terms();
  info.total = objective_.total();
}

// Densification and opacity resets on the 3DGS schedule in images seen (statistics gathered until densify_until,
// or to the end with late_prune, which then prunes alone).
void Trainer::densify_step(const StepPlan& plan, StepInfo& info) {
  if (!plan.gather_stats) return;
  stats_.add(step_stats_);
  // Each event at the image that names it, as 3DGS decides at its iteration k: densify when k % every == 0 and
  // densify_from < k < densify_until, reset opacities when k % reset_every == 0 and k < densify_until. A step of
  // several views that starts before densify_until may cover an image at or after it; that image is past the
  // schedule, as it is with one view per step.
  const int kd = event_image(plan.prev, it_, cfg_.densify_every);
  const bool grow = kd < cfg_.densify_until;
  if (kd > cfg_.densify_from && (grow || cfg_.late_prune > 0)) {
    release_step_buffers();
    if (grow) {
      const float screen = kd > cfg_.opacity_reset_every ? cfg_.screen_limit : 0.f;
      info.densify = densify_and_prune(model_, adam_, stats_, cfg_.densify_cfg, extent_, screen, rng_);
    } else {  // late_prune: footprints against the views' size, no world-size rule
      int side = 0;
      for (const TrainView& v : views_) side = std::max({side, v.cam.width, v.cam.height});
      DensifyConfig c = cfg_.densify_cfg;
      c.max_world_scale = std::numeric_limits<float>::infinity();
      info.densify = prune_step(model_, adam_, stats_, c, extent_, cfg_.late_prune * float(side));
    }
    info.densified = true;
  }
  const int kr = event_image(plan.prev, it_, cfg_.opacity_reset_every);
  const bool white_reset = cfg_.white_bg && plan.prev < cfg_.densify_from && it_ >= cfg_.densify_from &&
                           cfg_.densify_from < cfg_.densify_until;
  if ((kr > 0 && kr < cfg_.densify_until) || white_reset) reset_opacity(model_, adam_, 0.01f);
}

}  // namespace hgs::train
