#include "hybrid/association.h"

#include "core/error.h"
#include "hybrid/assign.h"
#include "model/render_inputs.h"
#include "render/camera_from_view.h"
#include "render/renderer.h"

namespace hgs::hybrid {

void hide_occluded_all(const GaussianModel& m, const std::vector<MaskView>& views, float near_plane,
                       ObservationTable& table, OcclusionScratch* scratch) {
  OcclusionScratch own;
  OcclusionScratch& w = scratch ? *scratch : own;
  render::GaussianInputs in = render_inputs(m);
  in.sh_degree = 0;  // colours do not matter here
  for (size_t u = 0; u < views.size(); ++u) {
    const MaskView& v = views[u];
    const render::Camera cam = render::pinhole_camera(v.width, v.height, v.fx, v.fy, v.cx, v.cy, v.R, v.t, near_plane);
    w.renderer.preprocess(cam, in);
    const size_t P = size_t(v.width) * v.height;
    w.chosen.assign(P, 0);
    occlusion_pixels(m.mean.data(), m.n, v, int(u), table, w.chosen.data());
    render::tile_pixels(v.width, v.height, w.chosen.data(), w.pixels);
    const long M = long(w.pixels.pixel.size());
    w.alpha.resize(size_t(M));
    w.depth.resize(size_t(M));
    w.renderer.depth_at(w.pixels, w.alpha.data(), w.depth.data());
    w.surface.resize(P);
    float* surface = w.surface.data();
    const int* pix = w.pixels.pixel.data();
    const float *alpha = w.alpha.data(), *depth = w.depth.data();
#pragma omp parallel for schedule(static)
    for (long i = 0; i < M; ++i) surface[pix[i]] = alpha[i] > 0.5f ? depth[i] / alpha[i] : 0.f;
    hide_occluded(m.mean.data(), m.n, v, surface, int(u), table);
  }
}

ObjectAssociation::ObjectAssociation(const HybridConfig& cfg, const std::vector<MaskView>* masks, int num_labels)
    : cfg_(cfg), masks_(masks), L_(num_labels) {
  const size_t U = masks_->size();
  logits_.assign(U, 0.f);
  w_.assign(U, 1.f / float(U));
}

void ObjectAssociation::attach(train::Adam& optim) {
  train::AdamParam& p = optim.add_array(kLogits, 1, int(logits_.size()), cfg_.lr_view, 1e-8f);
  p.values = [this] { return train::ParamValues{&logits_, nullptr}; };
}

void ObjectAssociation::fuse(int n, HybridFields& h) {
  s_.resize(size_t(n) * L_);
  valid_.resize(n);
  den_.resize(n);
  base_.resize(n);
  softmax(logits_.data(), int(logits_.size()), w_.data());
  FusionParams p{L_, cfg_.temperature, cfg_.fusion_eps, cfg_.background_vote};
  hybrid::fuse(table_, w_.data(), p, h.q->data.data(), s_.data(), valid_.data(), h.z->data.data(), den_.data(),
               base_.data());
}

const std::vector<float>& ObjectAssociation::weights() const {
  softmax(logits_.data(), int(logits_.size()), w_.data());
  return w_;
}

void ObjectAssociation::refresh(GaussianModel& m, HybridFields& h, float near_plane) {
  observe(m.mean.data(), m.n, *masks_, table_, near_plane);
  // The occlusion test applies to both assignments: the single-view one (no-OF ablation) then takes the label of
  // the first view where the centre is visible, so that the no-OF rows differ from the full method by eqs. 4-5
  // alone and Table 3's "OF added" measures fusion, not fusion and the occlusion test together.
  if (cfg_.occlusion_test) hide_occluded_all(m, *masks_, near_plane, table_, &occlusion_);
  if (cfg_.use_of) {
    fuse(m.n, h);  // q and z
  } else {
    single_view_assignment(table_, L_, h.q->data.data());
    update_hard_ids(m.n, h);
  }
}

void ObjectAssociation::update_hard_ids(int n, HybridFields& h) const {
  const float* q = h.q->data.data();
  float* zid = h.z->data.data();
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    uint16_t z;
    hard_ids(q + size_t(i) * L_, 1, L_, &z);
    zid[i] = float(z);
  }
}

void ObjectAssociation::backward(int /*n*/, const HybridFields& h, const float* dq, bool first) {
  if (!cfg_.use_of) return;
  const int U = static_cast<int>(logits_.size());
  FusionParams p{L_, cfg_.temperature, cfg_.fusion_eps, cfg_.background_vote};
  dw_.resize(U);
  dlogits_.resize(U);
  fuse_backward(table_, w_.data(), p, s_.data(), h.q->data.data(), valid_.data(), dq, dw_.data(),
                den_.size() == size_t(table_.n) ? den_.data() : nullptr);
  softmax_backward(w_.data(), dw_.data(), U, dlogits_.data());
  if (first) step_dlogits_ = dlogits_;
  else
    for (int u = 0; u < U; ++u) step_dlogits_[u] += dlogits_[u];
  step_set_ = true;
}

void ObjectAssociation::reduce(train::Reducer& r) {
  if (step_set_ && r.size() > 1) r.sum(step_dlogits_.data(), step_dlogits_.size());
}

void ObjectAssociation::update(train::Adam& optim, float scale) {
  if (!step_set_) return;
  step_set_ = false;
  if (scale != 1.f)
    for (float& g : step_dlogits_) g *= scale;
  optim.update(optim.get(kLogits), logits_.data(), step_dlogits_.data(), int(logits_.size()));
}

void ObjectAssociation::restore_table(int n, std::vector<uint16_t> labels) {
  table_.n = n;
  table_.num_views = int(logits_.size());
  table_.label = std::move(labels);
}

}  // namespace hgs::hybrid
