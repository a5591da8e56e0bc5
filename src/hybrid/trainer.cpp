#include "hybrid/trainer.h"

#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <random>

#include "core/error.h"
#include "core/half.h"
#include "core/parallel.h"
#include "hybrid/assign.h"
#include "hybrid/bro.h"
#include "hybrid/object_channels.h"
#include "hybrid/scl.h"
#include "render/sh.h"

namespace hgs::hybrid {

HybridTrainer::HybridTrainer(const train::TrainConfig& cfg, const HybridConfig& hcfg, GaussianModel model,
                             std::vector<train::TrainView> views, HybridData data, float extent)
    : Trainer(cfg, std::move(model), std::move(views), extent), hc_(hcfg), data_(std::move(data)) {
  L_ = data_.num_labels;
  D_ = data_.dim;
  const int U = static_cast<int>(views_.size());
  if (int(data_.masks.size()) != U || int(data_.views.size()) != U)
    fail("hybrid: {} training views but masks/features for {}", U, data_.masks.size());
  ExtraGroup* q = model_.find_extra("obj");
  if (!q) {
    q = &model_.add_extra("obj", L_, 0.f);
    for (int i = 0; i < model_.n; ++i) q->data[size_t(i) * L_] = 1.f;  // background until observed
  } else if (q->dim != L_) {
    fail("hybrid: the model has {} object channels but the masks have {} labels", q->dim, L_);
  }
  if (!model_.find_extra("obj_id")) model_.add_extra("obj_id", 1, 0.f);
  ExtraGroup* f = model_.find_extra("lang");
  if (!f) {
    f = &model_.add_extra("lang", D_, 0.f, hc_.lang_half);
    std::mt19937_64 rng(cfg.seed ^ 0x1A96ULL);
    std::normal_distribution<float> nd(0.f, hc_.lang_init_std);
    if (f->f16)
      for (auto& x : f->half) x = float_to_half(nd(rng));
    else
      for (auto& x : f->data) x = nd(rng);
  } else if (f->dim != D_) {
    fail("hybrid: the model's language embeddings have D = {} but the features have D = {}", f->dim, D_);
  } else if (f->f16 != hc_.lang_half) {  // e.g. a float32 PLY trained further in half precision
    std::vector<float> v = f->to_float();
    f->f16 = hc_.lang_half;
    if (f->f16) {
      f->half.resize(v.size());
      for (size_t k = 0; k < v.size(); ++k) f->half[k] = float_to_half(v[k]);
      std::vector<float>().swap(f->data);
    } else {
      f->data = std::move(v);
      std::vector<uint16_t>().swap(f->half);
    }
  }
  // f_n is optimised by a row-sparse Adam without a gradient buffer (semantic_contrastive / method_update);
  // by default f_n is stored in half precision and its moments in bfloat16.
  adam_.add("lang", D_, model_.n, hc_.lr_lang, hc_.lang_half);
  views_with_.assign(L_, {});
  for (int v = 0; v < int(data_.views.size()); ++v)
    for (int l : data_.views[v].fg) views_with_[l].push_back(v);
  logits_.assign(U, 0.f);
  w_.assign(U, 1.f / U);
  lm_.assign(U, 0.f);
  lv_.assign(U, 0.f);
  refresh_observations();
}

void HybridTrainer::fuse_now() {
  const int n = model_.n;
  s_.resize(size_t(n) * L_);
  valid_.resize(n);
  softmax(logits_.data(), int(logits_.size()), w_.data());
  FusionParams p{L_, hc_.temperature, hc_.fusion_eps};
  fuse(obs_, w_.data(), p, model_.find_extra("obj")->data.data(), s_.data(), valid_.data());
}

void HybridTrainer::refresh_observations() {
  observe(model_.mean.data(), model_.n, data_.masks, obs_);
  if (hc_.use_of) fuse_now();
  else single_view_assignment(obs_, L_, model_.find_extra("obj")->data.data());
  update_hard_ids();
}

void HybridTrainer::update_hard_ids() {
  const float* q = model_.find_extra("obj")->data.data();
  float* zid = model_.find_extra("obj_id")->data.data();
#pragma omp parallel for schedule(static)
  for (int i = 0; i < model_.n; ++i) {
    uint16_t z;
    hard_ids(q + size_t(i) * L_, 1, L_, &z);
    zid[i] = float(z);
  }
}

void HybridTrainer::prepare_inputs(const train::TrainView& view, render::GaussianInputs& in, render::RenderSettings& rs) {
  view_ = static_cast<int>(&view - views_.data());
  const int n = model_.n;
  const HybridView& hv = data_.views[view_];
  if (hc_.use_of) fuse_now();
  dq_.resize(size_t(n) * L_);
  parallel_fill(dq_, 0.f);
  // Colours by SH (all Gaussians; the renderer then takes them as precomputed colours).
  const float* R = view.cam.R;
  const float* t = view.cam.t;
  for (int c = 0; c < 3; ++c) campos_[c] = -(R[c] * t[0] + R[3 + c] * t[1] + R[6 + c] * t[2]);
  active_degree_ = in.sh_degree;
  colors_.resize(size_t(n) * 3);
  render::sh_forward(n, in.sh_degree, in.sh_stride, in.sh, in.mean, campos_, (const int*)nullptr, colors_.data());
  in.colors = colors_.data();
  // Object channels (+ the full semantic render for the no-SCL ablation).
  objs_ = hv.present;
  fg_ = (hc_.use_scl && hc_.lambda_sem > 0) ? hv.fg : std::vector<int>{};
  const int J = static_cast<int>(objs_.size());
  const int sem = (!hc_.use_scl && hc_.lambda_sem > 0) ? D_ : 0;
  lay_ = ObjectLayout{J, sem};
  C_ = lay_.total();
  extra_.resize(size_t(n) * C_);
  const float* q = model_.find_extra("obj")->data.data();
  object_channels(n, L_, lay_, objs_.data(), q, colors_.data(), extra_.data());
  if (sem) {
    const ExtraGroup& f = *model_.find_extra("lang");
#pragma omp parallel for schedule(static)
    for (int i = 0; i < n; ++i) f.row(i, &extra_[size_t(i) * C_ + lay_.other()]);
  }
  in.extra = extra_.data();
  in.num_extra = C_;
  // Pixel weights M_k of the SCL anchors: the rasterizer returns a_{n,k} = sum_p M_k(p) alpha_n T_n.
  const int W = view.cam.width, H = view.cam.height, Jf = static_cast<int>(fg_.size());
  if (Jf > 0) {
    const LabelMap& lab = data_.masks[view_].labels;
    pixel_w_.resize(size_t(W) * H * Jf);
#pragma omp parallel for schedule(static)
    for (size_t p = 0; p < lab.v.size(); ++p)
      for (int j = 0; j < Jf; ++j) pixel_w_[p * Jf + j] = lab.v[p] == fg_[j] ? 1.f : 0.f;
    rs.pixel_weights = pixel_w_.data();
    rs.num_pixel_weights = Jf;
  }
}

float HybridTrainer::appearance_and_bro(const train::TrainView& view, const render::RenderOutputs& out) {
  const int W = view.cam.width, H = view.cam.height, J = static_cast<int>(objs_.size());
  const size_t HW = size_t(W) * H;
  const LabelMap& lab = data_.masks[view_].labels;
  const bool bro_on = hc_.use_bro && hc_.lambda_bro > 0;
  obj_app_.assign(J, 0.0);
  obj_bro_.assign(J, 0.0);
  // Object images to planar [J][H, W, 3] (+ opacities [J][H, W]) in one pass over the interleaved render.
  obj_pred_.resize(size_t(J) * HW * 3);
  obj_grad_.resize(size_t(J) * HW * 3);
  obj_opac_.resize(size_t(J) * HW);
#pragma omp parallel for schedule(static)
  for (long p = 0; p < long(HW); ++p) {
    const float* e = &out.extra[size_t(p) * C_];
    for (int j = 0; j < J; ++j) {
      for (int c = 0; c < 3; ++c) obj_pred_[(size_t(j) * HW + p) * 3 + c] = e[lay_.color(j) + c];
      obj_opac_[size_t(j) * HW + p] = e[lay_.opacity(j)];
    }
  }
  // One object per thread (each object's SSIM and BRO run single-threaded in that thread's scratch): no
  // parallel-region overhead per convolution and each object's images stay in one core's cache. Loss values
  // are summed in object order (deterministic).
  const size_t threads = size_t(std::max(1, omp_get_max_threads()));
  if (scratch_.size() < threads) scratch_.resize(threads, ObjectScratch(hc_.lambda_dssim));
#pragma omp parallel for schedule(dynamic, 1)
  for (int j = 0; j < J; ++j) {
    ObjectScratch& w = scratch_[omp_get_thread_num()];
    w.gt.resize(HW * 3);
    w.mask.resize(HW);
    w.band.resize(HW);
    const float* pred = &obj_pred_[size_t(j) * HW * 3];
    float* grad = &obj_grad_[size_t(j) * HW * 3];
    const int k = objs_[j];
    for (size_t p = 0; p < HW; ++p) {
      const float m = lab.v[p] == k ? 1.f : 0.f;
      w.mask[p] = m;
      for (int c = 0; c < 3; ++c) w.gt[p * 3 + c] = view.image.px[p * 3 + c] * m;
    }
    train::LossValues lv = w.loss(pred, w.gt.data(), H, W, grad);
    obj_app_[j] = lv.total;
    const float s_app = hc_.lambda_app / J;
    for (size_t i = 0; i < HW * 3; ++i) grad[i] *= s_app;
    if (bro_on) {
      // B is built from the rendered opacity but treated as a constant: no gradient through the morphology.
      boundary_band(&obj_opac_[size_t(j) * HW], w.mask.data(), H, W, hc_.bro_kernel, w.band.data(), w.morph);
      const double band_total = band_weight_total(w.band.data(), H, W);
      const float f = hc_.bro_image_norm ? float(band_total / (2.0 * HW)) : 1.f;
      const float s_bro = f * hc_.lambda_bro / J;
      if (!hc_.bro_scale_invariant) {  // eq. 14's own gradient
        obj_bro_[j] = bro_loss(pred, w.gt.data(), 3, 3, w.band.data(), H, W, hc_.bro_eps, grad, s_bro, band_total);
      } else {  // the same value; its gradient without the component that scales the whole render (bro.h)
        w.bgrad.assign(HW * 3, 0.f);
        obj_bro_[j] =
            bro_loss(pred, w.gt.data(), 3, 3, w.band.data(), H, W, hc_.bro_eps, w.bgrad.data(), s_bro, band_total);
        remove_scale_component(pred, HW * 3, w.bgrad.data());
        for (size_t i = 0; i < HW * 3; ++i) grad[i] += w.bgrad[i];
      }
      obj_bro_[j] *= f;  // the term as optimised
    }
  }
  // Gradients back to the interleaved layout (the colour channels of a pixel are contiguous).
#pragma omp parallel for schedule(static)
  for (long p = 0; p < long(HW); ++p) {
    float* d = &d_extra_[size_t(p) * C_];
    for (int j = 0; j < J; ++j)
      for (int c = 0; c < 3; ++c) d[lay_.color(j) + c] += obj_grad_[(size_t(j) * HW + p) * 3 + c];
  }
  double app = 0, bro = 0;
  for (int j = 0; j < J; ++j) {
    app += obj_app_[j];
    bro += obj_bro_[j];
  }
  last_.app = J ? float(app / J) : 0.f;
  last_.bro = J ? float(bro / J) : 0.f;
  return hc_.lambda_app * last_.app + (hc_.use_bro ? hc_.lambda_bro * last_.bro : 0.f);
}

float HybridTrainer::semantic_contrastive(const render::RenderOutputs& out) {
  const int Jf = static_cast<int>(fg_.size()), n = model_.n;
  last_.anchors = 0;
  if (Jf == 0) return 0.f;
  if (int(out.weight_sums.size()) != n * Jf) fail("hybrid: the renderer returned no pixel-weighted sums");
  const HybridView& hv = data_.views[view_];
  std::vector<float> mass(Jf);
  for (int j = 0; j < Jf; ++j) mass[j] = hv.area[fg_[j]];
  P_.resize(size_t(Jf) * D_);
  dP_.assign(size_t(Jf) * D_, 0.f);
  const float* q = model_.find_extra("obj")->data.data();
  ExtraGroup& lang = *model_.find_extra("lang");
  auto lang_row = [&](long i, float* buf) -> const float* {  // f_i as float32 (widened from half storage)
    if (!lang.f16) return lang.data.data() + size_t(i) * D_;
    lang.row(size_t(i), buf);
    return buf;
  };
  pooled_prediction_rows(n, D_, L_, Jf, q, lang_row, out.weight_sums.data(), fg_.data(), mass.data(), 1e-6f, P_.data());
  // Anchor k in view u: positive from a random other view v whose mask holds k; negatives: v's other objects.
  struct Anchor { int j, v; };
  std::vector<Anchor> anchors;
  for (int j = 0; j < Jf; ++j) {
    // Views holding fg_[j] other than this one (view_ itself is in the list, so draw among the others).
    const std::vector<int>& cand = views_with_[fg_[j]];
    if (cand.size() < 2) continue;
    size_t pick = std::uniform_int_distribution<size_t>(0, cand.size() - 2)(rng_);
    if (cand[pick] >= view_) ++pick;
    anchors.push_back({j, cand[pick]});
  }
  last_.anchors = static_cast<int>(anchors.size());
  if (anchors.empty()) return 0.f;
  double loss = 0;
  const float scale = hc_.lambda_sem / anchors.size();
  for (auto [j, v] : anchors) {
    const HybridView& o = data_.views[v];
    std::vector<float>& refs = refs_;
    refs.resize(o.fg.size() * D_);
    int pos = 0;
    for (size_t r = 0; r < o.fg.size(); ++r) {
      std::copy(&o.zref[size_t(o.fg[r]) * D_], &o.zref[size_t(o.fg[r] + 1) * D_], &refs[r * D_]);
      if (o.fg[r] == fg_[j]) pos = int(r);
    }
    loss += info_nce(&P_[size_t(j) * D_], D_, refs.data(), int(o.fg.size()), pos, hc_.tau2, &dP_[size_t(j) * D_], scale);
  }
  // One pass over the Gaussians: da (the renderer's backward needs it, with sem_geometry only) and dq from the
  // dot products with the current f_n, then f_n's row-sparse Adam step on the same row, whose gradient
  // df_n = sum_j q a G_j needs no other part of the step (f enters no render here). Adam's step count for this
  // iteration is step_count + 1 (begin_step() runs later in Trainer::step).
  float* da = nullptr;
  if (hc_.sem_geometry) {
    d_wsum_.resize(size_t(n) * Jf);
    da = d_wsum_.data();
  }
  G_.resize(size_t(Jf) * D_);
  pooled_row_factors(Jf, D_, dP_.data(), mass.data(), 1e-6f, G_.data());
  const float* a = out.weight_sums.data();
  auto rows = [&](long i, float* g) {
    alignas(64) float buf[train::kMaxRowUpdateDim];
    return pooled_backward_row(i, D_, L_, Jf, q, lang_row(i, buf), a, fg_.data(), G_.data(), dq_.data(), da, g);
  };
  train::AdamParam& p = adam_.get("lang");
  if (lang.f16) adam_.update_rows(p, lang.half.data(), n, rows, adam_.step_count + 1);
  else adam_.update_rows(p, lang.data.data(), n, rows, adam_.step_count + 1);
  last_.sem = float(loss / anchors.size());
  return hc_.lambda_sem * last_.sem;
}

float HybridTrainer::semantic_cosine(const render::RenderOutputs& out) {
  // Full-scene semantic learning: mean over pixels of 1 - cos(S(p), S_ref(p)), S = sum_n f_n alpha T.
  const train::TrainView& view = views_[view_];
  const int W = view.cam.width, H = view.cam.height;
  const HybridView& hv = data_.views[view_];
  sref_ = upsample_bilinear(hv.patch_features.data(), hv.ph, hv.pw, D_, H, W);
  const size_t HW = size_t(W) * H;
  const int o = lay_.other();
  const float loss = cosine_loss(&out.extra[o], C_, sref_.data(), HW, D_, &d_extra_[o], hc_.lambda_sem);
  last_.sem = loss;
  last_.anchors = 0;
  return hc_.lambda_sem * last_.sem;
}

float HybridTrainer::extra_loss(const train::TrainView& view, const render::RenderOutputs& out, float* d_rgb,
                                render::OutputGrads& dout) {
  const int W = view.cam.width, H = view.cam.height;
  const size_t HW = size_t(W) * H;
  if (hc_.lambda_rgb != 1.f)
    for (size_t i = 0; i < HW * 3; ++i) d_rgb[i] *= hc_.lambda_rgb;
  d_extra_.resize(HW * C_);
  parallel_fill(d_extra_, 0.f);
  const auto t0 = std::chrono::steady_clock::now();
  float total = appearance_and_bro(view, out);
  const auto t1 = std::chrono::steady_clock::now();
  if (hc_.lambda_sem > 0) total += hc_.use_scl ? semantic_contrastive(out) : semantic_cosine(out);
  const auto t2 = std::chrono::steady_clock::now();
  last_.ms_app = std::chrono::duration<double, std::milli>(t1 - t0).count();
  last_.ms_sem = std::chrono::duration<double, std::milli>(t2 - t1).count();
  dout.extra = d_extra_.data();
  dout.extra_grad_channels = lay_.grad_channels();  // the opacity channels only shape BRO's constant band
  if (!fg_.empty() && last_.anchors > 0 && hc_.sem_geometry) dout.weight_sums = d_wsum_.data();
  return total;
}

void HybridTrainer::extra_param_grads(render::GaussianGrads& g) {
  const int n = model_.n;
  const float* q = model_.find_extra("obj")->data.data();
  // Object channels -> dq and dc (added to the RGB path's colour gradient), then SH.
  object_channels_backward(n, L_, lay_, objs_.data(), q, colors_.data(), g.extra.data(), dq_.data(), g.colors.data());
  g.sh.resize(size_t(n) * model_.sh_stride() * 3);
  render::sh_backward(n, active_degree_, model_.sh_stride(), model_.sh.data(), model_.mean.data(), campos_,
                      (const int*)nullptr, g.colors.data(), g.sh.data(), g.mean.data());
  if (hc_.use_of) {
    // dq -> view logits through eqs. 4-5 and the softmax over views; Adam on the logits.
    const int U = static_cast<int>(logits_.size());
    FusionParams p{L_, hc_.temperature, hc_.fusion_eps};
    dw_.resize(U);
    dlogits_.resize(U);
    fuse_backward(obs_, w_.data(), p, s_.data(), q, valid_.data(), dq_.data(), dw_.data());
    softmax_backward(w_.data(), dw_.data(), U, dlogits_.data());
    ++view_steps_;
    const float b1 = 0.9f, b2 = 0.999f, eps = 1e-8f;
    const float c1 = 1.f - std::pow(b1, float(view_steps_)), c2 = 1.f - std::pow(b2, float(view_steps_));
    for (int u = 0; u < U; ++u) {
      lm_[u] = b1 * lm_[u] + (1 - b1) * dlogits_[u];
      lv_[u] = b2 * lv_[u] + (1 - b2) * dlogits_[u] * dlogits_[u];
      logits_[u] -= hc_.lr_view * (lm_[u] / c1) / (std::sqrt(lv_[u] / c2) + eps);
    }
  }
}

void HybridTrainer::method_update() {
  // Row-sparse Adam on f_n for the no-SCL ablation: only Gaussians with a semantic gradient are updated.
  const int n = model_.n, D = D_;
  ExtraGroup& lang = *model_.find_extra("lang");
  train::AdamParam& p = adam_.get("lang");
  // (With SCL, f_n was updated in semantic_contrastive.)
  if (!hc_.use_scl && hc_.lambda_sem > 0) {
    // Full-scene semantic render: df_n is the gradient of its D extra channels.
    const float* ge = grads_.extra.data();
    auto rows = [&](long i, float* g) {
      const float* src = ge + size_t(i) * C_ + lay_.other();
      bool any = false;
      for (int d = 0; d < D; ++d) any |= (g[d] = src[d]) != 0.f;
      return any;
    };
    if (lang.f16) adam_.update_rows(p, lang.half.data(), n, rows);
    else adam_.update_rows(p, lang.data.data(), n, rows);
  }
}

void HybridTrainer::release_step_buffers() {
  Trainer::release_step_buffers();
  for (auto* v : {&s_, &dq_, &colors_, &extra_, &d_extra_, &pixel_w_, &d_wsum_, &obj_pred_, &obj_grad_, &obj_opac_})
    std::vector<float>().swap(*v);
}

std::vector<std::pair<std::string, std::vector<float>>> HybridTrainer::method_state() const {
  // Saved: the view logits and their Adam state, and the observation table (it reflects the centres of the
  // last refresh, so a resumed run continues bit for bit). Values are exact in float32.
  return {{"view_logits", logits_},
          {"view_adam_m", lm_},
          {"view_adam_v", lv_},
          {"view_adam_step", {float(view_steps_)}},
          {"observations", std::vector<float>(obs_.label.begin(), obs_.label.end())}};
}

void HybridTrainer::method_state_loaded(const std::string& where, const nlohmann::json& config, int n,
                                        std::map<std::string, std::vector<float>>& arrays) {
  // The checkpoint's hybrid options replace the current ones (as its TrainConfig does), except that SCL on or
  // off must agree: the no-SCL ablation needs the raw feature grids, loaded (or not) before the checkpoint.
  HybridConfig c = hc_;
  if (!config.is_null()) {
    c = HybridConfig::from_json(config);
    if (c.use_scl != hc_.use_scl)
      fail("{}: the checkpoint was trained {} --no-scl; resume with the same option", where, c.use_scl ? "without" : "with");
  }
  const size_t U = views_.size();
  const auto& lg = arrays["view_logits"];
  const auto& table = arrays["observations"];
  if (lg.size() != U || arrays["view_adam_m"].size() != U || arrays["view_adam_v"].size() != U ||
      arrays["view_adam_step"].size() != 1 || table.size() != size_t(n) * U)
    fail("{}: the hybrid state does not match {} training views and {} Gaussians", where, U, n);
  // Checked: take it.
  hc_ = c;
  scratch_.clear();  // its losses carry lambda_dssim
  logits_ = std::move(arrays["view_logits"]);
  lm_ = std::move(arrays["view_adam_m"]);
  lv_ = std::move(arrays["view_adam_v"]);
  view_steps_ = long(arrays["view_adam_step"][0]);
  obs_.n = n;
  obs_.num_views = int(U);
  obs_.label.assign(table.begin(), table.end());
  softmax(logits_.data(), int(U), w_.data());
}

void HybridTrainer::after_step(train::StepInfo& info) {
  if (info.densified || (hc_.fusion_every > 0 && iteration() % hc_.fusion_every == 0)) refresh_observations();
  else update_hard_ids();
}

}  // namespace hgs::hybrid
