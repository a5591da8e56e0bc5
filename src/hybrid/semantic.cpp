#include "hybrid/semantic.h"

#include <algorithm>
#include <cstring>

#include "core/error.h"
#include "core/parallel.h"
#include "hybrid/scl.h"

namespace hgs::hybrid {

SemanticPass::SemanticPass(const HybridConfig& cfg, const HybridData* data)
    : cfg_(cfg), data_(data), L_(data->num_labels), D_(data->dim) {
  views_with_.assign(L_, {});
  for (int v = 0; v < int(data_->views.size()); ++v)
    for (int l : data_->views[v].scl) views_with_[l].push_back(v);
}

std::vector<SclAnchor> draw_scl_anchors(const std::vector<int>& classes_u,
                                        const std::vector<std::vector<int>>& views_with, int u, std::mt19937_64& rng) {
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
  static const std::vector<int> none;
  const std::vector<int>& a = (cfg_.use_scl && cfg_.lambda_sem > 0) ? data_->views[u].scl : none;
  classes_ = a;
  return a;  // the data's own list: the renderer reads it until the view's backward (RenderSettings)
}

SemanticValues SemanticPass::contrastive(int u, int n, HybridFields& h, const float* a, float* dq, float* da,
                                         std::mt19937_64& rng, bool first) {
  if (first) views_.clear();
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
  if (lang.f16)  // the half rows converted as they are added (the same bits as widening them first)
    pooled_prediction_half(n, D_, L_, Jf, q, lang.half.data(), a, classes_.data(), mass.data(), 1e-6f, P_.data());
  else pooled_prediction_rows(n, D_, L_, Jf, q, lang_row, a, classes_.data(), mass.data(), 1e-6f, P_.data());
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
    loss +=
        info_nce(&P_[size_t(j) * D_], D_, refs_.data(), int(o.scl.size()), pos, cfg_.tau2, &dP_[size_t(j) * D_], scale);
  }
  // One pass over the Gaussians: da and dq from the dot products with the current f_n. f's own gradient waits
  // for update(), in factored form: every view of the step sees the same f.
  G_.resize(size_t(Jf) * D_);
  pooled_row_factors(Jf, D_, dP_.data(), mass.data(), 1e-6f, G_.data());
  FactoredView& fv = views_.emplace_back();
  fv.objs = classes_;
  fv.G = G_;
  // The same pass collects the Gaussians the view's masks touched (a row of a not all 0), in index order: a list
  // per chunk of rows (bounds from n alone), the lists joined in chunk order. A row of a all 0 has no dq term and
  // da 0 (pooled_backward_row's values), so its f_n is not read (a view's masks need not cover every Gaussian it
  // renders). Chunks on a dynamic schedule: the touched rows may cluster by index (densification appends its
  // clones at the end, a view sees some objects), which would leave threads of a static split idle. Every value
  // written is one row's own, so the schedule changes no bits.
  const FixedChunks chunks(n, 128, 512);
  if (touched_.size() < size_t(chunks.count)) touched_.resize(size_t(chunks.count));
#pragma omp parallel
  {
    alignas(64) float buf[train::kMaxRowUpdateDim];
#pragma omp for schedule(dynamic, 1)
    for (int c = 0; c < chunks.count; ++c) {
      std::vector<int>& mine = touched_[size_t(c)];
      mine.clear();
      for (long i = chunks.begin(c); i < chunks.end(c); ++i) {
        const float* ai = a + size_t(i) * Jf;
        if (std::none_of(ai, ai + Jf, [](float x) { return x != 0.f; })) {
          if (da) std::fill(da + size_t(i) * Jf, da + size_t(i + 1) * Jf, 0.f);
          continue;
        }
        mine.push_back(int(i));
        pooled_backward_row<float>(i, D_, L_, Jf, q, lang_row(i, buf), a, classes_.data(), G_.data(), dq, da);
      }
    }
  }
  std::vector<size_t> start(size_t(chunks.count) + 1, 0);
  for (int c = 0; c < chunks.count; ++c) start[size_t(c) + 1] = start[size_t(c)] + touched_[size_t(c)].size();
  fv.rows.resize(start.back());
  fv.a.resize(start.back() * Jf);
#pragma omp parallel for schedule(dynamic, 1)
  for (int c = 0; c < chunks.count; ++c) {
    const std::vector<int>& mine = touched_[size_t(c)];
    for (size_t r = 0; r < mine.size(); ++r) {
      const int i = mine[r];
      fv.rows[start[size_t(c)] + r] = i;
      std::copy_n(a + size_t(i) * Jf, Jf, &fv.a[(start[size_t(c)] + r) * Jf]);
    }
  }
  out.loss = loss / anchors.size();
  return out;
}

SemanticValues SemanticPass::cosine(int u, int W, int H, const float* extra, int C, int o, float* d_extra) {
  // Full-scene semantic learning: mean over pixels of 1 - cos(S(p), S_ref(p)), S = sum_n f_n alpha T.
  const HybridView& hv = data_->views[u];
  // S_ref(p): the view's feature grid upsampled to the image one pixel at a time (no [H, W, D] map per step).
  const float* grid = hv.patch_features.data();
  const int gh = hv.ph, gw = hv.pw, D = D_;
  auto ref = [=](size_t p, float* buf) { return bilinear_pixel(grid, gh, gw, D, H, W, p, buf); };
  SemanticValues out;
  out.loss = cosine_loss_rows(&extra[o], C, ref, size_t(W) * H, D_, &d_extra[o], cfg_.lambda_sem);
  return out;
}

void SemanticPass::add_channel_grads(int n, const float* ge, int C, int o, bool first) {
  const int D = D_;
  fgrad_.resize(size_t(n) * D);
  fgrad_set_ = true;
#pragma omp parallel for schedule(static)
  for (long i = 0; i < n; ++i) {
    const float* src = ge + size_t(i) * C + o;
    float* dst = &fgrad_[size_t(i) * D];
    for (int d = 0; d < D; ++d) dst[d] = first ? src[d] : dst[d] + src[d];
  }
}

namespace {

// The factored views as bytes: per view Jf, rows, objs [Jf], G [Jf, D], rows [rows], a [rows, Jf].
template <class V>
std::vector<uint8_t> pack_views(const std::vector<V>& views) {
  std::vector<uint8_t> b;
  auto put = [&](const void* p, size_t bytes) {
    const auto* c = static_cast<const uint8_t*>(p);
    // GCC 12 false positive: -Wstringop-overflow takes the insert into the empty vector as a write to 0 bytes.
#ifndef __clang__  // warnings clang does not have
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wstringop-overflow"
#endif
    b.insert(b.end(), c, c + bytes);
#ifndef __clang__
#pragma GCC diagnostic pop
#endif
  };
  const int32_t count = int32_t(views.size());
  put(&count, 4);
  for (const V& v : views) {
    const int32_t jf = int32_t(v.objs.size()), rows = int32_t(v.rows.size());
    put(&jf, 4);
    put(&rows, 4);
    put(v.objs.data(), 4 * v.objs.size());
    put(v.G.data(), 4 * v.G.size());
    put(v.rows.data(), 4 * v.rows.size());
    put(v.a.data(), 4 * v.a.size());
  }
  return b;
}

template <class V>
void unpack_views(const std::vector<uint8_t>& b, int D, std::vector<V>& out) {
  size_t o = 0;
  auto get = [&](void* p, size_t bytes) {
    if (o + bytes > b.size()) fail("hybrid: a rank sent a truncated semantic gradient");
    std::memcpy(p, b.data() + o, bytes);
    o += bytes;
  };
  int32_t count = 0;
  get(&count, 4);
  for (int32_t k = 0; k < count; ++k) {
    int32_t jf = 0, rows = 0;
    get(&jf, 4);
    get(&rows, 4);
    V& v = out.emplace_back();
    v.objs.resize(jf);
    v.G.resize(size_t(jf) * D);
    v.rows.resize(rows);
    v.a.resize(size_t(rows) * jf);
    get(v.objs.data(), 4 * v.objs.size());
    get(v.G.data(), 4 * v.G.size());
    get(v.rows.data(), 4 * v.rows.size());
    get(v.a.data(), 4 * v.a.size());
  }
}

}  // namespace

void SemanticPass::reduce(train::Reducer& r) {
  if (r.size() == 1) return;
  if (fgrad_set_) r.sum(fgrad_.data(), fgrad_.size());
  if (!cfg_.use_scl || cfg_.lambda_sem <= 0) return;
  const std::vector<std::vector<uint8_t>> all = r.gather(pack_views(views_));
  views_.clear();
  for (const auto& b : all) unpack_views(b, D_, views_);
}

void SemanticPass::update(int n, HybridFields& h, train::Adam& optim, float scale) {
  ExtraGroup& lang = *h.f;
  const int D = D_;
  train::AdamParam& p = optim.get(kParam);
  if (fgrad_set_) {  // no-SCL ablation: rows with a semantic gradient
    fgrad_set_ = false;
    if (fgrad_.size() != size_t(n) * D)
      fail("hybrid: the semantic gradient holds {} rows, the model {}", fgrad_.size() / D, n);
    auto rows = [&](long i, float* g) {
      const float* src = &fgrad_[size_t(i) * D];
      bool any = false;
      for (int d = 0; d < D; ++d) any |= (g[d] = scale == 1.f ? src[d] : src[d] * scale) != 0.f;
      return any;
    };
    if (lang.f16) optim.update_rows(p, lang.half.data(), n, rows);
    else optim.update_rows(p, lang.data.data(), n, rows);
    return;
  }
  if (views_.empty()) return;  // no anchors in any view of the step: f keeps its values and its step count
  // Where each view's rows are (-1 = not in that view's masks), on the threads (a view's rows are distinct).
  std::vector<ScratchVector<int>> pos(views_.size());
  for (size_t k = 0; k < views_.size(); ++k) {
    pos[k].resize(size_t(n));
    const ScratchVector<int>& rows = views_[k].rows;
    int* where = pos[k].data();
    long outside = -1;  // a row outside the model, if any
#pragma omp parallel
    {
#pragma omp for schedule(static)
      for (long i = 0; i < n; ++i) where[i] = -1;
#pragma omp for schedule(static) reduction(max : outside)
      for (long r = 0; r < long(rows.size()); ++r) {
        const int i = rows[r];
        if (i < 0 || i >= n) outside = std::max(outside, long(r));
        else where[i] = int(r);
      }
    }
    if (outside >= 0) fail("hybrid: a semantic gradient row {} is outside the {} Gaussians", rows[outside], n);
  }
  const float* q = h.q->data.data();
  const int L = L_;
  auto rows = [&](long i, float* g) {
    bool any = false;
    for (size_t k = 0; k < views_.size(); ++k) {
      const int r = pos[k][i];
      if (r < 0) continue;
      const FactoredView& v = views_[k];
      const int Jf = int(v.objs.size());
      any = pooled_df_row<float>(D, Jf, q + size_t(i) * L, &v.a[size_t(r) * Jf], v.objs.data(), v.G.data(), g, any);
    }
    if (any && scale != 1.f)
      for (int d = 0; d < D; ++d) g[d] *= scale;
    return any;
  };
  if (lang.f16) optim.update_rows(p, lang.half.data(), n, rows);
  else optim.update_rows(p, lang.data.data(), n, rows);
  views_.clear();
}

}  // namespace hgs::hybrid
