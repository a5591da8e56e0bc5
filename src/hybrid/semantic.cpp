#include "hybrid/semantic.h"

#include <algorithm>

#include "core/error.h"
#include "hybrid/scl.h"

namespace hgs::hybrid {

SemanticPass::SemanticPass(const HybridConfig& cfg, const HybridData* data)
    : cfg_(cfg), data_(data), L_(data->num_labels), D_(data->dim) {
  views_with_.assign(L_, {});
  for (int v = 0; v < int(data_->views.size()); ++v)
    for (int l : data_->views[v].scl) views_with_[l].push_back(v);
}

std::vector<SclAnchor> draw_scl_anchors(const std::vector<int>& classes_u, const std::vector<std::vector<int>>& views_with,
                                        int u, std::mt19937_64& rng) {
  std::vector<SclAnchor> anchors;
  for (int j = 0; j < int(classes_u.size()); ++j) {
    // Views holding the class other than u (u itself is in the ascending list, so draw among the others).
    const std::vector<int>& cand = views_with[classes_u[j]];
    if (cand.size() < 2) continue;
    size_t pick = std::uniform_int_distribution<size_t>(0, cand.size() - 2)(rng);
    if (cand[pick] >= u) ++pick;
    anchors.push_back({j, cand[pick]});
  }
  return anchors;
}

const std::vector<int>& SemanticPass::anchors_of(int u) {
  classes_ = (cfg_.use_scl && cfg_.lambda_sem > 0) ? data_->views[u].scl : std::vector<int>{};
  return classes_;
}

const float* SemanticPass::pixel_weights(int u) {
  const int Jf = static_cast<int>(classes_.size());
  if (Jf == 0) return nullptr;
  const LabelMap& lab = data_->masks[u].labels;
  pixel_w_.resize(lab.v.size() * Jf);
#pragma omp parallel for schedule(static)
  for (size_t p = 0; p < lab.v.size(); ++p)
    for (int j = 0; j < Jf; ++j) pixel_w_[p * Jf + j] = lab.v[p] == classes_[j] ? 1.f : 0.f;
  return pixel_w_.data();
}

SemanticValues SemanticPass::contrastive(int u, int n, HybridFields& h, const float* a, float* dq, float* da,
                                         std::mt19937_64& rng, train::Adam& optim) {
  SemanticValues out;
  const int Jf = static_cast<int>(classes_.size());
  if (Jf == 0) return out;
  if (!a) fail("hybrid: the renderer returned no pixel-weighted sums");
  const HybridView& hv = data_->views[u];
  std::vector<float> mass(Jf);
  for (int j = 0; j < Jf; ++j) mass[j] = hv.area[classes_[j]];
  P_.resize(size_t(Jf) * D_);
  dP_.assign(size_t(Jf) * D_, 0.f);
  const float* q = h.q->data.data();
  ExtraGroup& lang = *h.f;
  auto lang_row = [&](long i, float* buf) -> const float* {  // f_i as float32 (widened from half storage)
    if (!lang.f16) return lang.data.data() + size_t(i) * D_;
    lang.row(size_t(i), buf);
    return buf;
  };
  pooled_prediction_rows(n, D_, L_, Jf, q, lang_row, a, classes_.data(), mass.data(), 1e-6f, P_.data());
  // Anchor k in view u: positive from a random other view v whose SCL classes hold k; negatives: v's others.
  const std::vector<SclAnchor> anchors = draw_scl_anchors(classes_, views_with_, u, rng);
  out.anchors = static_cast<int>(anchors.size());
  if (anchors.empty()) return out;
  double loss = 0;
  const float scale = cfg_.lambda_sem / anchors.size();
  for (auto [j, v] : anchors) {
    const HybridView& o = data_->views[v];
    refs_.resize(o.scl.size() * D_);
    int pos = 0;
    for (size_t r = 0; r < o.scl.size(); ++r) {
      std::copy(&o.zref[size_t(o.scl[r]) * D_], &o.zref[size_t(o.scl[r] + 1) * D_], &refs_[r * D_]);
      if (o.scl[r] == classes_[j]) pos = int(r);
    }
    loss += info_nce(&P_[size_t(j) * D_], D_, refs_.data(), int(o.scl.size()), pos, cfg_.tau2, &dP_[size_t(j) * D_], scale);
  }
  // One pass over the Gaussians: da and dq from the dot products with the current f_n, then f_n's row-sparse
  // Adam step on the same row, whose gradient df_n = sum_j q a G_j needs no other part of the step (f enters
  // no render here).
  G_.resize(size_t(Jf) * D_);
  pooled_row_factors(Jf, D_, dP_.data(), mass.data(), 1e-6f, G_.data());
  auto rows = [&](long i, float* g) {
    alignas(64) float buf[train::kMaxRowUpdateDim];
    return pooled_backward_row(i, D_, L_, Jf, q, lang_row(i, buf), a, classes_.data(), G_.data(), dq, da, g);
  };
  train::AdamParam& p = optim.get(kParam);
  if (lang.f16) optim.update_rows(p, lang.half.data(), n, rows);
  else optim.update_rows(p, lang.data.data(), n, rows);
  out.loss = loss / anchors.size();
  return out;
}

SemanticValues SemanticPass::cosine(int u, int W, int H, const float* extra, int C, int o, float* d_extra) {
  // Full-scene semantic learning: mean over pixels of 1 - cos(S(p), S_ref(p)), S = sum_n f_n alpha T.
  const HybridView& hv = data_->views[u];
  sref_ = upsample_bilinear(hv.patch_features.data(), hv.ph, hv.pw, D_, H, W);
  SemanticValues out;
  out.loss = cosine_loss(&extra[o], C, sref_.data(), size_t(W) * H, D_, &d_extra[o], cfg_.lambda_sem);
  return out;
}

void SemanticPass::update_from_channels(int n, HybridFields& h, const float* ge, int C, int o, train::Adam& optim) {
  // Row-sparse Adam on f_n: only Gaussians with a semantic gradient are updated.
  ExtraGroup& lang = *h.f;
  const int D = D_;
  auto rows = [&](long i, float* g) {
    const float* src = ge + size_t(i) * C + o;
    bool any = false;
    for (int d = 0; d < D; ++d) any |= (g[d] = src[d]) != 0.f;
    return any;
  };
  train::AdamParam& p = optim.get(kParam);
  if (lang.f16) optim.update_rows(p, lang.half.data(), n, rows);
  else optim.update_rows(p, lang.data.data(), n, rows);
}

}  // namespace hgs::hybrid
