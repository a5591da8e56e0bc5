// Observation Fusion (paper eqs. 2-5).
//
// observe():  projects every Gaussian centre into every training view (eq. 3) and records the mask label at the
//             projected pixel, or "no observation" when the depth is not positive or the pixel is outside the
//             image (V_{n,u} = 0). Masks are the confidence-filtered label maps, so M_{u,k}(p) = [label = k] and
//             M_{u,0} = 1 - OR_k M_{u,k} holds by construction. The table is rebuilt every R iterations and after
//             densification; it does not depend on the view weights.
//             Deviation (HybridConfig::unconfident_unobserved, on by default): a pixel whose confidence is below
//             tau1 is no observation (V_{n,u} = 0) rather than background. As written, eq. 2 turns every
//             unconfident pixel into background evidence, and SAM2's confidence is lowest on object rims and on
//             small objects, so under noise the background out-votes the object for many of its own Gaussians
//             (docs/results.md, "Observation Fusion under noise"); an unconfident pixel says nothing about either.
//             Deviation (HybridConfig::occlusion_test, on by default): V_{n,u} also requires the centre to be
//             visible, not more than kOcclusionTolerance behind the surface the view sees at p_{n,u} (the
//             current model's rendered depth; hide_occluded). Eq. 3 projects a hidden Gaussian onto its
//             occluder, whose label (often background) then votes for it.
// fuse():     w = softmax(view logits) ("learnable normalised reliability"),
//             s_{n,k} = sum_u w_u V_{n,u} b_k M_{u,k}(p_{n,u}) / (sum_u w_u V_{n,u} + eps)    (eq. 4)
//             b_0 = FusionParams::background_vote, b_k = 1 for objects; the paper has b_0 = 1.
//             Deviation (HybridConfig::background_vote, default 0.5, with the occlusion test): M_{u,0} =
//             1 - OR_k M_{u,k} is not an observation of the background but the absence of every mask, and a
//             missed or eroded object (common for small objects in SAM2's masks) produces it; with b_0 = 1 a small
//             object's own Gaussians lose the vote to the background under heavy mask noise (docs/results.md
//             sections 5-8). With b_0 = 0.5 an object wins with more than a third of the views that see it. Without
//             the occlusion test, Gaussians hidden behind an object (the table under a mug) then take its label
//             and objects bloat (section 8).
//             q_n = softmax(s_n / T), z_n = argmax_k q_{n,k}                                  (eq. 5)
//             Gaussians without any valid view keep their previous q (and z).
// fuse_backward(): exact dL/dlogits from dL/dq through eqs. 4-5 and the softmax over views (Gaussians without a
//             valid view pass no gradient: their q is a constant).
// Templated on the scalar so the tests check the gradient in double precision.
#pragma once
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include "core/image.h"

namespace hgs::hybrid {

constexpr uint16_t kNoObservation = 0xFFFF;

// A training view's camera and its confidence-filtered label map.
struct MaskView {
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  double R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // world -> camera, row-major
  double t[3] = {0, 0, 0};
  LabelMap labels;                // [H, W] in 0..K
  std::vector<uint8_t> observed;  // [H, W] 0 where the pixel is no observation (V = 0); empty = every pixel
};

// Occlusion test (hide_occluded): a Gaussian whose centre lies more than this fraction behind the surface at its
// projected pixel is hidden in that view (no observation).
constexpr double kOcclusionTolerance = 0.05;

// labels[k] = 0 wherever confidence < tau1 (conf may be empty: no filtering). [H, W]
void apply_confidence(LabelMap& labels, const std::vector<float>& conf, float tau1);
// observed[p] = conf[p] >= tau1 ([H, W]; empty when conf is empty).
std::vector<uint8_t> confident_pixels(const std::vector<float>& conf, float tau1);

struct ObservationTable {
  int n = 0, num_views = 0;
  std::vector<uint16_t> label;  // [N, U]: observed label, or kNoObservation
};

// means [N, 3]
void observe(const float* means, int n, const std::vector<MaskView>& views, ObservationTable& table);
// Marks view u's observations of Gaussians hidden behind the surface as none. surface_depth [H, W] (0 = no
// surface: no test there).
void hide_occluded(const float* means, int n, const MaskView& view, const float* surface_depth, int u,
                   ObservationTable& table);

template <class T>
void softmax(const T* x, int n, T* y) {
  T m = x[0];
  for (int i = 1; i < n; ++i) m = std::max(m, x[i]);
  T s = 0;
  for (int i = 0; i < n; ++i) s += (y[i] = std::exp(x[i] - m));
  for (int i = 0; i < n; ++i) y[i] /= s;
}

// dx = y * (dy - <y, dy>) for y = softmax(x).
template <class T>
void softmax_backward(const T* y, const T* dy, int n, T* dx) {
  T d = 0;
  for (int i = 0; i < n; ++i) d += y[i] * dy[i];
  for (int i = 0; i < n; ++i) dx[i] = y[i] * (dy[i] - d);
}

struct FusionParams {
  int num_labels = 2;            // K + 1
  double temperature = 0.1;      // T of eq. 5
  double eps = 1e-6;             // epsilon of eq. 4
  double background_vote = 1.0;  // weight of a background observation in eq. 4's numerator (1 = the paper)
};

// w [U] (already softmax-normalised), q [N, K+1] in/out (kept where no view is valid), s [N, K+1] out,
// valid [N] out (1 if some view observed the Gaussian).
template <class T>
void fuse(const ObservationTable& tab, const T* w, const FusionParams& p, T* q, T* s, uint8_t* valid) {
  const int L = p.num_labels, U = tab.num_views;
#pragma omp parallel for schedule(static)
  for (int n = 0; n < tab.n; ++n) {
    const uint16_t* lab = &tab.label[size_t(n) * U];
    T* sn = s + size_t(n) * L;
    std::fill(sn, sn + L, T(0));
    T den = 0;
    for (int u = 0; u < U; ++u) {
      if (lab[u] == kNoObservation) continue;
      den += w[u];
      if (lab[u] < L) sn[lab[u]] += lab[u] == 0 ? T(p.background_vote) * w[u] : w[u];
    }
    valid[n] = den > 0;
    if (!valid[n]) continue;
    const T inv = T(1) / (den + T(p.eps));
    T logits[256];
    T* lg = L <= 256 ? logits : nullptr;
    std::vector<T> big;
    if (!lg) {
      big.resize(L);
      lg = big.data();
    }
    for (int k = 0; k < L; ++k) {
      sn[k] *= inv;
      lg[k] = sn[k] / T(p.temperature);
    }
    softmax(lg, L, q + size_t(n) * L);
  }
}

// dq [N, K+1] -> dw [U] (dL/dw, overwritten). s, q, valid from fuse().
template <class T>
void fuse_backward(const ObservationTable& tab, const T* w, const FusionParams& p, const T* s, const T* q,
                   const uint8_t* valid, const T* dq, T* dw) {
  const int L = p.num_labels, U = tab.num_views;
  std::fill(dw, dw + U, T(0));
  // Per-thread partial sums, added in thread order (deterministic for a given thread count).
  std::vector<std::vector<T>> partial(size_t(std::max(1, omp_get_max_threads())));
#pragma omp parallel
  {
    std::vector<T>& dw_local = partial[omp_get_thread_num()];
    dw_local.assign(U, T(0));
    std::vector<T> ds(L);
#pragma omp for schedule(static)
    for (int n = 0; n < tab.n; ++n) {
      if (!valid[n]) continue;
      const T* qn = q + size_t(n) * L;
      const T* sn = s + size_t(n) * L;
      softmax_backward(qn, dq + size_t(n) * L, L, ds.data());
      T den = 0;
      const uint16_t* lab = &tab.label[size_t(n) * U];
      for (int u = 0; u < U; ++u)
        if (lab[u] != kNoObservation) den += w[u];
      const T inv = T(1) / (den + T(p.eps));
      // ds/ds_logit scale 1/T; d s_k / d w_u = V_u ([label_u = k] - s_k) / (den + eps)
      T sum_ds_s = 0;
      for (int k = 0; k < L; ++k) {
        ds[k] /= T(p.temperature);
        sum_ds_s += ds[k] * sn[k];
      }
      for (int u = 0; u < U; ++u) {
        if (lab[u] == kNoObservation) continue;
        T g = -sum_ds_s;
        if (lab[u] < L) g += lab[u] == 0 ? T(p.background_vote) * ds[0] : ds[lab[u]];
        dw_local[u] += g * inv;
      }
    }
  }
  for (const auto& part : partial)
    for (int u = 0; u < U; ++u) dw[u] += part[u];
}

// z_n = argmax_k q_{n,k} (first maximum). q [N, K+1] -> z [N]
template <class T>
void hard_ids(const T* q, int n, int num_labels, uint16_t* z) {
  for (int i = 0; i < n; ++i) {
    const T* qi = q + size_t(i) * num_labels;
    z[i] = static_cast<uint16_t>(std::max_element(qi, qi + num_labels) - qi);
  }
}

}  // namespace hgs::hybrid
