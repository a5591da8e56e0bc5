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
#include <immintrin.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <string>
#include <type_traits>
#include <vector>

#include "core/image.h"
#include "core/parallel.h"
#include "hybrid/object_channels.h"
#include "render/renderer.h"

// The blocked loops below return 8-lane vectors of double (512 bits) from lambdas; GCC notes that their ABI differs
// without AVX-512 (-Wpsabi), which does not matter for functions inlined into one translation unit.
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wpsabi"

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
// The unlabelled pixels (label 0) that HybridConfig::gaps makes no observation: [H, W] 1 at such a pixel, or empty
// when the view's gaps stay background evidence ("background"; "auto" in a view whose masks label less than
// kGapsCoverage of its pixels).
constexpr double kGapsCoverage = 0.9;
std::vector<uint8_t> gap_pixels(const LabelMap& labels, const std::string& gaps);

struct ObservationTable {
  int n = 0, num_views = 0;
  std::vector<uint16_t> label;  // [N, U]: observed label, or kNoObservation
};

// Eq. 3's V and the labels: Gaussian n is observed in view u when its centre projects into the image at a
// camera-space depth of at least near_plane (the training cameras': the renderer culls nearer centres, so that
// view never sees it). means [N, 3]
void observe(const float* means, int n, const std::vector<MaskView>& views, ObservationTable& table,
             double near_plane = render::kDefaultNearPlane);
// Marks view u's observations of Gaussians hidden behind the surface as none. surface_depth [H, W] (0 = no
// surface: no test there), read only at the pixels occlusion_pixels() chooses.
void hide_occluded(const float* means, int n, const MaskView& view, const float* surface_depth, int u,
                   ObservationTable& table);
// The pixels hide_occluded() will read for view u: chosen [H, W] is set to 1 at each observed Gaussian's pixel
// (the caller zeroes it first), so the surface depth is needed there only (render::RendererT::depth_at).
void occlusion_pixels(const float* means, int n, const MaskView& view, int u, const ObservationTable& table,
                      uint8_t* chosen);

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

// softmax() bitwise, for a row whose entries are mostly +-0 (eq. 5's logits of the labels no view observed):
// exp(0 - m) is computed once and reused (0 - m and -0 - m differ only when m = 0, and exp(+-0) = 1 alike).
template <class T>
void softmax_zeros_once(const T* x, int n, T* y) {
  T m = x[0];
  for (int i = 1; i < n; ++i) m = std::max(m, x[i]);
  T s = 0, e0 = T(-1);  // exp(0 - m) once known (an exp is never negative)
  for (int i = 0; i < n; ++i) {
    T e;
    if (x[i] == T(0)) {
      if (e0 < T(0)) e0 = std::exp(x[i] - m);
      e = e0;
    } else {
      e = std::exp(x[i] - m);
    }
    s += (y[i] = e);
  }
  for (int i = 0; i < n; ++i) y[i] /= s;
}

// z = argmax_k q_k (the first maximum) of one row q [L].
template <class T>
uint16_t hard_id(const T* q, int num_labels) {
  return static_cast<uint16_t>(std::max_element(q, q + num_labels) - q);
}

// Eq. 5 for one Gaussian from its unnormalised sums acc [L] (strided by `stride`) and den: s_n [L], q_n [L],
// valid, and z_n = argmax q_n when z is not null (of the row kept when no view is valid). lg [L] scratch.
template <class T>
void fuse_finish(const T* acc, int stride, T den, const FusionParams& p, T* sn, T* qn, uint8_t& valid, T* lg,
                 float* z) {
  const int L = p.num_labels;
  for (int k = 0; k < L; ++k) sn[k] = acc[size_t(k) * stride];
  valid = den > 0;
  if (valid) {
    const T inv = T(1) / (den + T(p.eps));
    for (int k = 0; k < L; ++k) {
      sn[k] *= inv;
      lg[k] = sn[k] / T(p.temperature);
    }
    softmax_zeros_once(lg, L, qn);
  }
  if (z) *z = float(hard_id(qn, L));
}

// Blocks of 8 Gaussians, one per vector lane, for fuse() and fuse_backward(): V holds one value of each, VI their
// labels in one view.
template <class T>
struct FuseBlock {
  static constexpr int B = 8;
  using I = std::conditional_t<sizeof(T) == 4, int32_t, int64_t>;
  typedef T V __attribute__((vector_size(sizeof(T) * B)));
  typedef I VI __attribute__((vector_size(sizeof(T) * B)));
  // View u's labels of the block's nb Gaussians (rows [nb, U] of the table) into lb; lanes past nb: no observation.
  // (An out-parameter: a 64-byte vector returned by value would change the ABI between ISA levels.)
  static void labels(const uint16_t* rows, int U, int u, int nb, VI& lb) {
    for (int b = 0; b < B; ++b) lb[b] = b < nb ? I(rows[size_t(b) * U + u]) : I(kNoObservation);
  }
};

// w [U] (already softmax-normalised), q [N, K+1] in/out (kept where no view is valid), s [N, K+1] out,
// valid [N] out (1 if some view observed the Gaussian), z [N] out when not null: argmax q (hard_ids' values, as
// float: the model's hard-id group), den [N] out when not null: eq. 4's normaliser sum_u w_u V_{n,u} (before eps),
// which fuse_backward() then reads instead of summing it again, base [N] out when not null: the smallest of each
// row of q (base_association of object_channels.h, which the object channels of every view of the step need).
// Up to kFuseBlockLabels labels, the sums of eq. 4 run over blocks of 8 Gaussians, one per lane, each label's sum
// in registers: every view adds its weight (or 0) to the sum of every label that some view of the block observed
// (a Gaussian sees a few of the labels; the others' sums stay +0). A Gaussian's sums then run in view order with
// zeros in between, so they are those of the per-Gaussian loop bitwise, without its unpredictable branches and its
// read-modify-writes of one label's sum view after view (a chain of store-to-load latencies).
constexpr int kFuseBlockLabels = 96;
template <class T>
void fuse(const ObservationTable& tab, const T* w, const FusionParams& p, T* q, T* s, uint8_t* valid,
          float* z = nullptr, T* den_out = nullptr, T* base_out = nullptr) {
  const int L = p.num_labels, U = tab.num_views, N = tab.n;
  const T bv = T(p.background_vote);
  if (L <= kFuseBlockLabels) {
    using FB = FuseBlock<T>;
    using I = typename FB::I;
    using V = typename FB::V;  // 8 Gaussians' sums of one label
    constexpr int B = FB::B;
    const int blocks = (N + B - 1) / B;
#pragma omp parallel
    {
      V acc[kFuseBlockLabels];   // (a vector type loses its attribute as a template argument: no std::vector)
      int ks[kFuseBlockLabels];  // the labels some view of the block observed, ascending
      V sv[kFuseBlockLabels], ev[kFuseBlockLabels];
      std::vector<I> lt(size_t(U) * B);  // the block's labels [U, B]
      // Eq. 4's normalisation and eq. 5 for the block's lanes at once: each lane's operations are fuse_finish's in
      // its order (vector division and max round and compare as their scalar forms), the softmax's exps scalar per
      // lane with exp(0 - m) once; s, q and z then go to the rows. A lane without any observation keeps its q.
      auto finish = [&](const V* acc, const int* ks, int nk, V den, int n0, int nb) {
        const V inv = (V{} + T(1)) / (den + T(p.eps));
        for (int k = 0; k < L; ++k) sv[k] = V{};
        for (int i = 0; i < nk; ++i) sv[ks[i]] = acc[i] * inv;         // (an absent label's +0 * inv is +0)
        for (int k = 0; k < L; ++k) ev[k] = sv[k] / T(p.temperature);  // the logits first, then their exps in place
        V m = ev[0];
        for (int k = 1; k < L; ++k) m = m < ev[k] ? ev[k] : m;
        V e0;
        for (int b = 0; b < B; ++b) e0[b] = std::exp(T(0) - m[b]);
        for (int k = 0; k < L; ++k)
          for (int b = 0; b < B; ++b) ev[k][b] = ev[k][b] == T(0) ? e0[b] : std::exp(ev[k][b] - m[b]);
        V sum{};
        for (int k = 0; k < L; ++k) sum += ev[k];
        for (int k = 0; k < L; ++k) ev[k] /= sum;
        V best = ev[0], arg{}, low = ev[0];  // the first maximum, as hard_id; the minimum, as base_association
        for (int k = 1; k < L; ++k) {
          const auto up = best < ev[k];
          best = up ? ev[k] : best;
          arg = up ? V{} + T(k) : arg;
          low = ev[k] < low ? ev[k] : low;
        }
        for (int b = 0; b < nb; ++b) {
          const size_t n = size_t(n0 + b);
          T *sn = s + n * L, *qn = q + n * L;
          if (den_out) den_out[n] = den[b];
          valid[n] = den[b] > 0;
          if (!valid[n]) {  // no view: s is the zero sums, q stays
            std::fill(sn, sn + L, T(0));
            if (z) z[n] = float(hard_id(qn, L));
            if (base_out) base_out[n] = base_association(qn, L);
            continue;
          }
          for (int k = 0; k < L; ++k) sn[k] = sv[k][b], qn[k] = ev[k][b];
          if (z) z[n] = float(arg[b]);
          if (base_out) base_out[n] = low[b];
        }
      };
      // On demand (demand_chunk): a block's cost follows the labels its Gaussians observed.
#pragma omp for schedule(dynamic, demand_chunk(blocks, 16))
      for (int blk = 0; blk < blocks; ++blk) {
        const int n0 = blk * B, nb = std::min(B, N - n0);
        const uint16_t* rows = &tab.label[size_t(n0) * U];
        // One pass over the block's labels: transposed view by view, so that each sum below runs down the views
        // in a register (summing every label's in one pass over the views kept the sums in memory, each view's add
        // waiting on the last store), and which labels occur, a byte each (labels past the last and no observation
        // share the last byte, never read; plain stores: setting bits of a word in memory made each entry wait on
        // the last).
        uint8_t seen[kFuseBlockLabels + 1] = {};
        for (int u = 0; u < U; ++u)
          for (int b = 0; b < B; ++b) {
            const unsigned l = b < nb ? rows[size_t(b) * U + u] : kNoObservation;
            lt[size_t(u) * B + b] = I(l);
            seen[std::min<unsigned>(l, kFuseBlockLabels)] = 1;
          }
        int nk = 0;
        for (int k = 0; k < L; ++k)
          if (seen[k]) ks[nk++] = k;
        auto labels = [&](int u) {
          typename FB::VI v;
          __builtin_memcpy(&v, &lt[size_t(u) * B], sizeof v);
          return v;
        };
        V den{};
        for (int u = 0; u < U; ++u) den += labels(u) != I(kNoObservation) ? V{} + w[u] : V{};
        for (int i = 0; i < nk; ++i) {
          const I k = I(ks[i]);
          V a{};
          if (k == 0)  // the background's votes weighted by background_vote
            for (int u = 0; u < U; ++u) a += labels(u) == k ? V{} + bv * w[u] : V{};
          else
            for (int u = 0; u < U; ++u) a += labels(u) == k ? V{} + w[u] : V{};
          acc[i] = a;
        }
        finish(acc, ks, nk, den, n0, nb);
      }
    }
    return;
  }
#pragma omp parallel
  {
    std::vector<T> acc(L), lg(L);
#pragma omp for schedule(static)
    for (int n = 0; n < N; ++n) {
      const uint16_t* lab = &tab.label[size_t(n) * U];
      std::fill(acc.begin(), acc.end(), T(0));
      T den = 0;
      for (int u = 0; u < U; ++u) {
        if (lab[u] == kNoObservation) continue;
        den += w[u];
        if (lab[u] < L) acc[lab[u]] += lab[u] == 0 ? bv * w[u] : w[u];
      }
      if (den_out) den_out[n] = den;
      fuse_finish(acc.data(), 1, den, p, s + size_t(n) * L, q + size_t(n) * L, valid[n], lg.data(),
                  z ? z + n : nullptr);
      if (base_out) base_out[n] = base_association(q + size_t(n) * L, L);
    }
  }
}

// dq [N, K+1] -> dw [U] (dL/dw, overwritten). s, q, valid and (when not null) den from fuse() with the same w.
template <class T>
void fuse_backward(const ObservationTable& tab, const T* w, const FusionParams& p, const T* s, const T* q,
                   const uint8_t* valid, const T* dq, T* dw, const T* den_in = nullptr) {
  const int L = p.num_labels, U = tab.num_views, N = tab.n;
  using FB = FuseBlock<T>;  // blocks of Gaussians: their normalisers as in fuse(), then their views
  using I = typename FB::I;
  using V = typename FB::V;
  constexpr int B = FB::B;
  const int blocks = (N + B - 1) / B;
  // A partial [U] per fixed chunk of blocks, added in chunk order: the same bits at any thread count.
  chunked_sum(FixedChunks(blocks, 128, 64), size_t(U), dw, [&](long blk0, long blk1, T* dw_local) {
    // gv [B, L + 2]: the gradient of a view that observes the Gaussian with label l, before the factor 1 / (den +
    // eps) (background weighted; a label outside [0, L) gets only the normalisation's part, slot L), slot L + 1 = 0
    // for no observation.
    std::vector<T> ds(L), gv(size_t(B) * (L + 2));
    for (long blk = blk0; blk < blk1; ++blk) {
      const int n0 = int(blk) * B, nb = std::min(B, N - n0);
      // The Gaussians that pass a gradient: valid (elsewhere q is a constant) and with some dq != 0. A row of dq
      // all +-0 (a Gaussian this step did not render, or no loss reached) makes every term below +-0, and adding
      // +-0 to a sum that starts at +0 leaves it as it was (such a sum is never -0): skipped, the same bits.
      bool live[B] = {}, any = false;
      for (int b = 0; b < nb; ++b) {
        const T* d = dq + size_t(n0 + b) * L;
        live[b] = valid[n0 + b] && std::any_of(d, d + L, [](T x) { return x != T(0); });
        any |= live[b];
      }
      if (!any) continue;
      const uint16_t* rows = &tab.label[size_t(n0) * U];
      V den{};  // fuse()'s, or summed again in view order as fuse() sums it
      if (den_in) {
        for (int b = 0; b < nb; ++b) den[b] = den_in[n0 + b];
      } else {
        for (int u = 0; u < U; ++u) {
          typename FB::VI lb;
          FB::labels(rows, U, u, nb, lb);
          den += lb != I(kNoObservation) ? V{} + w[u] : V{};
        }
      }
      T inv_b[B] = {};
      for (int b = 0; b < nb; ++b) {
        const size_t n = size_t(n0 + b);
        T* g = &gv[size_t(b) * (L + 2)];
        if (!live[b]) continue;
        std::fill(g, g + L + 2, T(0));
        softmax_backward(q + n * L, dq + n * L, L, ds.data());
        const T inv = T(1) / (den[b] + T(p.eps));
        // ds/ds_logit scale 1/T; d s_k / d w_u = V_u ([label_u = k] - s_k) / (den + eps)
        T sum_ds_s = 0;
        const T* sn = s + n * L;
        for (int k = 0; k < L; ++k) {
          ds[k] /= T(p.temperature);
          sum_ds_s += ds[k] * sn[k];
        }
        // (written as the per-view formula -sum + b_k ds_k, then times inv where it is added, so that the values
        // are those of a loop over the views, ObservationFusion.BlockedFusionIsThePerGaussianLoopBitwise)
        g[0] = -sum_ds_s + T(p.background_vote) * ds[0];
        for (int k = 1; k < L; ++k) g[k] = -sum_ds_s + ds[k];
        g[L] = -sum_ds_s;
        inv_b[b] = inv;
      }
      // Gaussian by Gaussian (the order of the per-Gaussian loop), its views independent of each other.
      for (int b = 0; b < nb; ++b) {
        if (!live[b]) continue;
        const T* g = &gv[size_t(b) * (L + 2)];
        const T inv = inv_b[b];
        const uint16_t* lab = rows + size_t(b) * U;
        T* d = dw_local;
        int u = 0;
#ifdef __AVX2__
        if constexpr (std::is_same_v<T, float>) {  // 8 views at once: each d[u] gets the same fused multiply-add
          const __m256i none = _mm256_set1_epi32(kNoObservation), past = _mm256_set1_epi32(L),
                        slot_none = _mm256_set1_epi32(L + 1);
          const __m256 vinv = _mm256_set1_ps(inv);
          for (; u + 8 <= U; u += 8) {
            const __m256i l = _mm256_cvtepu16_epi32(_mm_loadu_si128(reinterpret_cast<const __m128i*>(lab + u)));
            const __m256i slot = _mm256_blendv_epi8(_mm256_min_epu32(l, past), slot_none, _mm256_cmpeq_epi32(l, none));
            _mm256_storeu_ps(d + u, _mm256_fmadd_ps(_mm256_i32gather_ps(g, slot, 4), vinv, _mm256_loadu_ps(d + u)));
          }
        }
#endif
        for (; u < U; ++u) {
          const int l = lab[u];
          d[u] += g[l == kNoObservation ? L + 1 : l < L ? l : L] * inv;
        }
      }
    }
  });
}

// z_n = argmax_k q_{n,k} (first maximum). q [N, K+1] -> z [N]
template <class T>
void hard_ids(const T* q, int n, int num_labels, uint16_t* z) {
  for (int i = 0; i < n; ++i) z[i] = hard_id(q + size_t(i) * num_labels, num_labels);
}

}  // namespace hgs::hybrid

#pragma GCC diagnostic pop
