// Finite-difference checks (double precision) for the hybrid method's own gradients: Observation Fusion to
// the view logits, object channels, pooled semantics, InfoNCE and BRO; plus hand-made Observation Fusion cases.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <functional>
#include <random>

#include "core/half.h"
#include "fd_check.h"
#include "hybrid/association.h"
#include "hybrid/bro.h"
#include "hybrid/fusion.h"
#include "hybrid/object_channels.h"
#include "hybrid/scl.h"
#include "model/gaussian_model.h"
#include "model/render_inputs.h"
#include "render/camera_from_view.h"
#include "render/renderer.h"
#include "scene/scene.h"

using namespace hgs;
using namespace hgs::hybrid;

namespace {

// Central differences of f at x for every coordinate, within 1e-6 of the largest |analytic| plus 1e-9 of
// `analytic`; some difference must exceed 1e-8 (a zero gradient would pass otherwise).
void check_grad(std::vector<double>& x, const std::function<double()>& f, const std::vector<double>& analytic) {
  const test::FdStats st =
      test::fd_check("coordinate", x, test::all_indices(x.size()), analytic, f,
                     {.h = 1e-6, .rtol = 0, .scale_atol = 1e-6, .atol = 1e-9, .noise_atol = 0, .nonzero_fd = 1e-8});
  EXPECT_GT(st.nonzero, 0) << "the check would pass for a zero gradient";
}

std::vector<double> randv(size_t n, std::mt19937& rng, double lo = -1, double hi = 1) {
  std::uniform_real_distribution<double> u(lo, hi);
  std::vector<double> v(n);
  for (auto& x : v) x = u(rng);
  return v;
}

// A camera at the origin looking down +z (identity pose): 10x10 image, f = 10, principal point (5, 5), every
// pixel labelled `label`.
MaskView pinhole_view(uint16_t label) {
  MaskView v;
  v.width = v.height = 10;
  v.fx = v.fy = 10;
  v.cx = v.cy = 5;
  v.labels = LabelMap(10, 10, label);
  return v;
}

}  // namespace

TEST(ObservationFusion, GradientToViewLogits) {
  std::mt19937 rng(1);
  const int N = 30, U = 6, L = 4;
  ObservationTable tab;
  tab.n = N;
  tab.num_views = U;
  tab.label.resize(N * U);
  for (auto& l : tab.label) l = rng() % 5 == 0 ? kNoObservation : uint16_t(rng() % L);
  for (int u = 0; u < U; ++u) tab.label[u] = kNoObservation;  // Gaussian 0 has no valid view
  for (double background_vote : {1.0, 0.4}) {
    SCOPED_TRACE(background_vote);
    FusionParams p{L, 0.3, 1e-6, background_vote};
    std::vector<double> logits = randv(U, rng), dq = randv(N * L, rng), q0(N * L, 0.25);
    auto loss = [&](std::vector<double>* q_out, std::vector<double>* s_out, std::vector<uint8_t>* valid_out) {
      std::vector<double> w(U), q = q0, s(N * L);
      std::vector<uint8_t> valid(N);
      softmax(logits.data(), U, w.data());
      fuse(tab, w.data(), p, q.data(), s.data(), valid.data());
      double l = 0;
      for (int i = 0; i < N * L; ++i) l += dq[i] * q[i];
      if (q_out) *q_out = q, *s_out = s, *valid_out = valid;
      return l;
    };
    std::vector<double> q, s, w(U), dw(U), dlogits(U);
    std::vector<uint8_t> valid;
    loss(&q, &s, &valid);
    EXPECT_EQ(valid[0], 0);
    for (int k = 0; k < L; ++k) EXPECT_EQ(q[k], 0.25);  // kept
    softmax(logits.data(), U, w.data());
    fuse_backward(tab, w.data(), p, s.data(), q.data(), valid.data(), dq.data(), dw.data());
    softmax_backward(w.data(), dw.data(), U, dlogits.data());
    check_grad(
        logits, [&] { return loss(nullptr, nullptr, nullptr); }, dlogits);
  }
}

// Eqs. 4-5 and their backward written per Gaussian and per view, as the paper states them (the reference for the
// blocked, branch-free fuse / fuse_backward).
template <class T>
void fuse_reference(const ObservationTable& tab, const T* w, const FusionParams& p, T* q, T* s, uint8_t* valid) {
  const int L = p.num_labels, U = tab.num_views;
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
    std::vector<T> lg(L);
    for (int k = 0; k < L; ++k) {
      sn[k] *= inv;
      lg[k] = sn[k] / T(p.temperature);
    }
    softmax(lg.data(), L, q + size_t(n) * L);
  }
}
// dw is summed Gaussian by Gaussian within each of fuse_backward's fixed chunks (of 8-Gaussian blocks; their bounds
// depend on N alone), and the chunks' sums are added in chunk order.
template <class T>
void fuse_backward_reference(const ObservationTable& tab, const T* w, const FusionParams& p, const T* s, const T* q,
                             const uint8_t* valid, const T* dq, T* dw) {
  const int L = p.num_labels, U = tab.num_views, B = FuseBlock<T>::B;
  const FixedChunks chunks((tab.n + B - 1) / B, 128, 64);
  std::fill(dw, dw + U, T(0));
  std::vector<T> ds(L), part(U);
  for (int c = 0; c < chunks.count; ++c) {
    std::fill(part.begin(), part.end(), T(0));
    for (int n = int(chunks.begin(c)) * B; n < std::min<long>(tab.n, chunks.end(c) * B); ++n) {
      if (!valid[n]) continue;
      softmax_backward(q + size_t(n) * L, dq + size_t(n) * L, L, ds.data());
      const uint16_t* lab = &tab.label[size_t(n) * U];
      T den = 0;
      for (int u = 0; u < U; ++u)
        if (lab[u] != kNoObservation) den += w[u];
      const T inv = T(1) / (den + T(p.eps));
      T sum_ds_s = 0;
      for (int k = 0; k < L; ++k) {
        ds[k] /= T(p.temperature);
        sum_ds_s += ds[k] * s[size_t(n) * L + k];
      }
      for (int u = 0; u < U; ++u) {
        if (lab[u] == kNoObservation) continue;
        T g = -sum_ds_s;
        if (lab[u] < L) g += lab[u] == 0 ? T(p.background_vote) * ds[0] : ds[lab[u]];
        part[u] += g * inv;
      }
    }
    for (int u = 0; u < U; ++u) dw[u] += part[u];
  }
}

// fuse() sums eq. 4 for 8 Gaussians at once, branch-free, over the labels some view of the block observed, and
// eq. 5's softmax computes exp(0 - m) once; fuse_backward() likewise runs over blocks (fusion.h): on one thread
// both give the per-Gaussian loops' values bit for bit, for a Gaussian count that is not a multiple of 8, labels
// past the last one (counted only in the normaliser), Gaussians without any observation, rows of dq all zero, a
// label count above kFuseBlockLabels (the per-Gaussian path), and tables whose Gaussians see every label or a few
// (each its own label, the background and now and then another: most labels absent from a block). z, written
// with q, is hard_ids() of the reference's q, and the base association its smallest value; fuse_backward() with
// fuse()'s normalisers is the reference too. fuse_backward's sum over Gaussians gives the reference's bits at 1, 2
// and 3 threads, in one chunk (N = 301) and in several (N = 3373, four chunks).
// Float and double.
template <class T>
void blocked_fusion_case(int N) {
  std::mt19937 rng(4);
  for (bool clustered : {false, true})
    for (int L : {2, 9, 40, kFuseBlockLabels + 5}) {
      SCOPED_TRACE(testing::Message() << "N " << N << ", L " << L << (clustered ? ", clustered" : ", spread"));
      const int U = 37;
      ObservationTable tab;
      tab.n = N;
      tab.num_views = U;
      tab.label.resize(size_t(N) * U);
      for (int n = 0; n < N; ++n) {
        const uint16_t own = uint16_t(rng() % L);
        for (int u = 0; u < U; ++u) {
          const unsigned r = rng() % 10;
          uint16_t& l = tab.label[size_t(n) * U + u];
          if (clustered)
            l = r < 3 ? kNoObservation : r < 5 ? 0 : r == 5 && rng() % 4 == 0 ? uint16_t(rng() % (L + 2)) : own;
          else l = r < 3 ? kNoObservation : r < 5 ? 0 : r == 5 ? uint16_t(L + rng() % 3) : uint16_t(rng() % L);
        }
      }
      for (int u = 0; u < U; ++u) tab.label[size_t(7) * U + u] = kNoObservation;  // Gaussian 7: no valid view
      // Gaussian 9: observed, but only as a label past the last: every s_k is 0, q uniform, z the first label.
      for (int u = 0; u < U; ++u) tab.label[size_t(9) * U + u] = uint16_t(L);
      std::uniform_real_distribution<T> R(0, 1);
      std::vector<T> w(U), dq(size_t(N) * L), dw(U), dw_ref(U);
      for (auto& x : w) x = R(rng) / U;
      for (auto& x : dq) x = R(rng) - 0.5f;
      // Rows of dq all zero, as for the Gaussians a step does not render (fuse_backward skips them): every third
      // Gaussian, a whole block of 8 (16..23), and rows of -0; the reference adds their terms.
      for (int n = 0; n < N; ++n)
        if (n % 3 == 0 || (n >= 16 && n < 24) || n % 5 == 1)
          std::fill_n(&dq[size_t(n) * L], L, n % 5 == 1 ? T(-0.0) : T(0));
      const FusionParams p{L, 0.1, 1e-6, 0.5};
      std::vector<T> q(size_t(N) * L, T(0.3)), s(q.size()), q_ref = q, s_ref(q.size());
      q[size_t(7) * L + L - 1] = q_ref[size_t(7) * L + L - 1] = T(0.4);  // kept: z = the last label
      std::vector<uint8_t> valid(N), valid_ref(N);
      std::vector<float> z(N, -1.f);
      const int threads = omp_get_max_threads();
      omp_set_num_threads(1);
      std::vector<T> den(N, T(-1)), dw_den(U), base(N, T(-1));
      fuse(tab, w.data(), p, q.data(), s.data(), valid.data(), z.data(), den.data(), base.data());
      fuse_backward(tab, w.data(), p, s.data(), q.data(), valid.data(), dq.data(), dw.data());
      fuse_backward(tab, w.data(), p, s.data(), q.data(), valid.data(), dq.data(), dw_den.data(), den.data());
      std::vector<std::vector<T>> dw_at;  // at 2 and 3 threads
      for (int t : {2, 3}) {
        omp_set_num_threads(t);
        fuse_backward(tab, w.data(), p, s.data(), q.data(), valid.data(), dq.data(), dw_at.emplace_back(U).data());
      }
      omp_set_num_threads(threads);
      fuse_reference(tab, w.data(), p, q_ref.data(), s_ref.data(), valid_ref.data());
      fuse_backward_reference(tab, w.data(), p, s_ref.data(), q_ref.data(), valid_ref.data(), dq.data(), dw_ref.data());
      EXPECT_EQ(valid, valid_ref);
      EXPECT_EQ(valid[7], 0);
      EXPECT_EQ(s, s_ref);
      EXPECT_EQ(q, q_ref);
      EXPECT_EQ(dw, dw_ref);
      EXPECT_EQ(dw_den, dw_ref);  // fuse()'s normalisers instead of summing them again
      for (const auto& d : dw_at) EXPECT_EQ(std::memcmp(d.data(), dw_ref.data(), U * sizeof(T)), 0);
      EXPECT_NE(dw, std::vector<T>(U, T(0)));
      EXPECT_EQ(den[7], T(0));  // no view
      EXPECT_GT(den[9], T(0));  // views of labels past the last count in the normaliser
      std::vector<uint16_t> z_ref(N);
      hard_ids(q_ref.data(), N, L, z_ref.data());
      EXPECT_EQ(z, std::vector<float>(z_ref.begin(), z_ref.end()));
      EXPECT_EQ(z[7], float(L - 1));
      for (int n = 0; n < N; ++n) ASSERT_EQ(base[n], base_association(&q_ref[size_t(n) * L], L)) << n;
      EXPECT_EQ(valid[9], 1);
      EXPECT_EQ(z[9], 0.f);
      // The clustered tables leave most labels out of most blocks (what the label list skips).
      if (clustered && L == 40) {
        int absent = 0;
        for (int n = 0; n < N; ++n) absent += int(std::count(&s[size_t(n) * L], &s[size_t(n + 1) * L], T(0)));
        EXPECT_GT(absent, N * L / 2);
      }
    }
}

TEST(ObservationFusion, BlockedFusionIsThePerGaussianLoopBitwise) {
  for (int N : {301, 128 * 8 * 3 + 301}) {
    blocked_fusion_case<float>(N);
    blocked_fusion_case<double>(N);
  }
}

TEST(ObservationFusion, BackgroundVoteWeighsTheAbsenceOfAMask) {
  // Five views of one Gaussian: two masks say object 1, three say background (a missed or eroded small object).
  // Eq. 4 as written (background_vote 1): s = (0.6, 0.4), the background wins. With background_vote 0.5 the
  // background's numerator halves, s = (0.3, 0.4): the object wins. A Gaussian seen as background in every view
  // stays background at any vote weight; object votes are never discounted.
  ObservationTable tab;
  tab.n = 2;
  tab.num_views = 5;
  tab.label = {1, 0, 1, 0, 0,  //
               0, 0, 0, 0, 0};
  const float w[] = {0.2f, 0.2f, 0.2f, 0.2f, 0.2f};
  for (double bv : {1.0, 0.5}) {
    SCOPED_TRACE(bv);
    FusionParams p{2, 0.05, 1e-9, bv};
    std::vector<float> q(4, 0.5f), s(4);
    std::vector<uint8_t> valid(2);
    fuse(tab, w, p, q.data(), s.data(), valid.data());
    EXPECT_NEAR(s[0], 0.6 * bv, 1e-6);
    EXPECT_NEAR(s[1], 0.4, 1e-6);
    EXPECT_EQ(q[1] > q[0], bv < 1.0);
    EXPECT_NEAR(s[2], bv, 1e-6);
    EXPECT_NEAR(s[3], 0.0, 1e-6);
    EXPECT_GT(q[2], q[3]);
  }
}

TEST(ObservationFusion, HandMadeCases) {
  // One camera at the origin looking down +z, 10x10 image, left half labelled 1, right half 2;
  // a second identical camera whose mask says 0 everywhere.
  MaskView v = pinhole_view(0);
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 10; ++x) v.labels.at(x, y) = x < 5 ? 1 : 2;
  MaskView bg = v;
  bg.labels = LabelMap(10, 10, 0);
  const float means[] = {
      -0.2f, 0.f, 1.f,   // left -> 1
      0.2f,  0.f, 1.f,   // right -> 2
      0.f,   0.f, -1.f,  // behind the camera
      3.f,   0.f, 1.f,   // outside the image
  };
  ObservationTable tab;
  observe(means, 4, {v, bg}, tab);
  EXPECT_EQ(tab.label[0], 1);
  EXPECT_EQ(tab.label[1], 0);
  EXPECT_EQ(tab.label[2], 2);
  EXPECT_EQ(tab.label[4], kNoObservation);
  EXPECT_EQ(tab.label[5], kNoObservation);
  EXPECT_EQ(tab.label[6], kNoObservation);
  // Equal weights: Gaussian 0 has s = (0.5, 0.5, 0); with w = (0.9, 0.1) the reliable view wins.
  FusionParams p{3, 0.1, 1e-9};
  std::vector<float> q(12, 0.f), s(12);
  q[9] = 1.f;  // Gaussian 3 (never observed) keeps its previous association
  std::vector<uint8_t> valid(4);
  float w_eq[] = {0.5f, 0.5f};
  fuse(tab, w_eq, p, q.data(), s.data(), valid.data());
  EXPECT_NEAR(s[0], 0.5f, 1e-6);
  EXPECT_NEAR(s[1], 0.5f, 1e-6);
  EXPECT_NEAR(q[0], q[1], 1e-6);
  EXPECT_EQ(valid[2], 0);
  EXPECT_EQ(valid[3], 0);
  EXPECT_EQ(q[9], 1.f);
  float w_rel[] = {0.9f, 0.1f};
  fuse(tab, w_rel, p, q.data(), s.data(), valid.data());
  std::vector<uint16_t> z(4);
  hard_ids(q.data(), 4, 3, z.data());
  EXPECT_EQ(z[0], 1);  // s = (0.1, 0.9, 0): the reliable view (label 1) wins
  EXPECT_NEAR(s[1], 0.9f, 1e-5);
  EXPECT_EQ(std::max_element(q.begin(), q.begin() + 3) - q.begin(), 1);
  EXPECT_EQ(z[3], 0);  // kept q = (1, 0, 0)
}

TEST(ObservationFusion, UnconfidentPixelsAreNoObservationNotBackground) {
  // Three identical cameras see one object (label 1) over the whole 10x10 image. In two of them the pixel under
  // the Gaussian has confidence below tau1 (a rim pixel of SAM2's mask). Eq. 2 as written makes those pixels
  // background, so the background wins 2:1; as no observation, the one confident view decides.
  MaskView v = pinhole_view(1);
  std::vector<float> conf(100, 0.9f);
  std::vector<float> rim = conf;
  rim[5 * 10 + 5] = 0.3f;                                  // the pixel (5, 5) the Gaussian projects to
  const float means[] = {0.f, 0.f, 1.f, 0.3f, 0.3f, 1.f};  // Gaussian 1 projects to (8, 8), confident everywhere
  FusionParams p{2, 0.05, 1e-9};
  const float w[] = {1.f / 3, 1.f / 3, 1.f / 3};
  for (bool unobserved : {false, true}) {
    std::vector<MaskView> views(3, v);
    for (int u = 0; u < 3; ++u) {
      const std::vector<float>& c = u < 2 ? rim : conf;
      apply_confidence(views[u].labels, c, 0.5f);
      if (unobserved) views[u].observed = confident_pixels(c, 0.5f);
    }
    ObservationTable tab;
    observe(means, 2, views, tab);
    std::vector<float> q(4, 0.5f), s(4);
    std::vector<uint8_t> valid(2);
    fuse(tab, w, p, q.data(), s.data(), valid.data());
    SCOPED_TRACE(unobserved ? "unobserved" : "background");
    EXPECT_EQ(tab.label[0], unobserved ? kNoObservation : 0);
    EXPECT_EQ(tab.label[2], 1);
    EXPECT_NEAR(s[1], unobserved ? 1.f : 1.f / 3, 1e-5);  // s_{0,1}
    EXPECT_EQ(q[1] > q[0], unobserved);                   // object wins only when rims are no observation
    EXPECT_NEAR(s[3], 1.f, 1e-5);                         // Gaussian 1: confident in every view either way
  }
  EXPECT_EQ(confident_pixels({}, 0.5f).size(), 0u);
}

TEST(ObservationFusion, HiddenGaussiansAreNoObservation) {
  // A camera at the origin looking down +z sees a surface at depth 2 on the left half of a 10x10 image and
  // nothing on the right. Gaussians: in front of the surface, just behind it (within the 5 % tolerance), well
  // behind it, and behind nothing.
  MaskView v = pinhole_view(1);
  std::vector<float> depth(100, 0.f);
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 5; ++x) depth[y * 10 + x] = 2.f;
  const float means[] = {-0.2f, 0.f, 1.f, -0.4f, 0.f, 2.08f, -0.6f, 0.f, 3.f, 0.6f, 0.f, 3.f};
  ObservationTable tab;
  observe(means, 4, {v}, tab);
  for (int i = 0; i < 4; ++i) ASSERT_EQ(tab.label[i], 1) << i;
  hide_occluded(means, 4, v, depth.data(), 0, tab);
  EXPECT_EQ(tab.label[0], 1);
  EXPECT_EQ(tab.label[1], 1);
  EXPECT_EQ(tab.label[2], kNoObservation);
  EXPECT_EQ(tab.label[3], 1);
}

TEST(ObservationFusion, TheTrainingNearPlaneInObservationsAndOcclusion) {
  // An opaque wall 0.1 in front of the camera covering the image, and a small opaque Gaussian at depth 2 behind it.
  // At the default plane the wall is observed, is the surface and hides the Gaussian. With the cameras' plane at
  // 0.2 the renderer culls the wall (training never shows it): it is no observation (eq. 3's V = 0) and no surface,
  // so the Gaussian behind it is the surface and stays observed.
  GaussianModel m;
  m.sh_degree = 0;
  m.resize(2);
  m.mean = {0.f, 0.f, 0.1f, 0.f, 0.f, 2.f};
  m.log_scale = {-1.f, -1.f, -4.f, -2.f, -2.f, -2.f};
  m.quat = {1.f, 0.f, 0.f, 0.f, 1.f, 0.f, 0.f, 0.f};
  m.opacity_logit = {6.f, 6.f};
  m.sh.assign(6, 1.f);
  const std::vector<MaskView> views = {pinhole_view(1)};
  for (float plane : {render::kDefaultNearPlane, 0.2f}) {
    SCOPED_TRACE(plane);
    ObservationTable tab;
    observe(m.mean.data(), m.n, views, tab, plane);
    EXPECT_EQ(tab.label[0], plane > 0.1f ? kNoObservation : 1);
    ASSERT_EQ(tab.label[1], 1);
    hide_occluded_all(m, views, plane, tab);
    EXPECT_EQ(tab.label[0], plane > 0.1f ? kNoObservation : 1);  // the wall is never behind anything
    EXPECT_EQ(tab.label[1], plane > 0.1f ? 1 : kNoObservation);
  }
  // The plane applies to the centre's depth: just in front of it, no observation; at it, observed.
  ObservationTable tab;
  observe(m.mean.data(), m.n, views, tab, 0.1000001);
  EXPECT_EQ(tab.label[0], kNoObservation);
  observe(m.mean.data(), m.n, views, tab, 0.0999999);
  EXPECT_EQ(tab.label[0], 1);
}

// The occlusion test composites the depth at the pixels it reads only (render::RendererT::depth_at). Against the
// test as it was, a whole depth render per view and the surface at every pixel: the same table, for a few
// thousand Gaussians in three views of odd sizes (partial tiles). The kept scratch starts with a surface that
// would hide everything, so a pixel the test reads but did not composite would show.
TEST(ObservationFusion, OcclusionAtTheTestedPixelsIsTheWholeRendersTest) {
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> U(0, 1);
  const int n = 4000;
  GaussianModel m;
  m.sh_degree = 0;
  m.resize(n);
  for (int i = 0; i < n; ++i) {
    m.mean[3 * i] = 2.4f * U(rng) - 1.2f;
    m.mean[3 * i + 1] = 1.8f * U(rng) - 0.9f;
    m.mean[3 * i + 2] = 1.5f + 3.f * U(rng);
    for (int k = 0; k < 3; ++k) m.log_scale[3 * i + k] = std::log(0.01f + 0.06f * U(rng));
    m.quat[4 * i] = 1.f;
    m.quat[4 * i + 1] = U(rng) - 0.5f;
    m.opacity_logit[i] = 6.f * U(rng) - 2.f;
  }
  std::vector<MaskView> views;
  for (auto [w, h] : {std::pair{101, 67}, std::pair{64, 48}, std::pair{37, 53}}) {
    MaskView v;
    v.width = w;
    v.height = h;
    v.fx = v.fy = 0.9 * w;
    v.cx = 0.5 * w;
    v.cy = 0.5 * h;
    v.t[0] = 0.1 * views.size();
    v.labels = LabelMap(w, h, uint16_t(views.size() + 1));
    views.push_back(std::move(v));
  }
  ObservationTable want;
  observe(m.mean.data(), n, views, want);
  ObservationTable got = want;
  render::GaussianInputs in = render_inputs(m);
  render::GaussianRenderer r;
  render::RenderOutputs out;
  for (size_t u = 0; u < views.size(); ++u) {
    const MaskView& v = views[u];
    r.forward(render::pinhole_camera(v.width, v.height, v.fx, v.fy, v.cx, v.cy, v.R, v.t), in, render::RenderSettings{},
              out);
    std::vector<float> surface(out.alpha.size());
    for (size_t p = 0; p < surface.size(); ++p) surface[p] = out.alpha[p] > 0.5f ? out.depth[p] / out.alpha[p] : 0.f;
    hide_occluded(m.mean.data(), n, v, surface.data(), int(u), want);
  }
  OcclusionScratch scratch;
  scratch.surface.assign(size_t(101) * 67, 1e-3f);  // in front of every centre
  hide_occluded_all(m, views, render::kDefaultNearPlane, got, &scratch);
  EXPECT_EQ(got.label, want.label);
  const ObservationTable before = [&] {
    ObservationTable t;
    observe(m.mean.data(), n, views, t);
    return t;
  }();
  long hidden = 0, kept = 0;
  for (size_t e = 0; e < want.label.size(); ++e) {
    hidden += before.label[e] != kNoObservation && want.label[e] == kNoObservation;
    kept += want.label[e] != kNoObservation;
  }
  EXPECT_GT(hidden, 100);  // the test hides many entries and keeps many
  EXPECT_GT(kept, 100);
}

TEST(ObjectChannels, GradientToQAndColour) {
  std::mt19937 rng(2);
  const int N = 7, L = 5, J = 3;
  const ObjectLayout lay{J, 2};  // 2 other channels between the colours and the opacities
  const int stride = lay.total();
  ASSERT_EQ(stride, 14);
  EXPECT_EQ(lay.opacity(0), 11);
  EXPECT_EQ(lay.grad_channels(), 11);
  const int objs[J] = {0, 2, 4};
  std::vector<double> q = randv(N * L, rng, 0, 1), c = randv(N * 3, rng, 0, 1), up = randv(N * stride, rng);
  auto loss = [&] {
    std::vector<double> e(N * stride, 0.0);
    object_channels(N, L, lay, objs, q.data(), c.data(), e.data());
    double l = 0;
    for (int i = 0; i < N * stride; ++i) l += up[i] * e[i];
    return l;
  };
  // The other channels are not written, so their upstream gradient must not matter.
  for (int i = 0; i < N; ++i) up[i * stride + 9] = up[i * stride + 10] = 0;
  std::vector<double> e(N * stride, -1.0);
  object_channels(N, L, lay, objs, q.data(), c.data(), e.data());
  EXPECT_EQ(e[9], -1.0);
  EXPECT_EQ(e[lay.opacity(1)], q[2]);           // Gaussian 0, object 2
  EXPECT_EQ(e[lay.color(2) + 1], q[4] * c[1]);  // Gaussian 0, object 4, green
  std::vector<double> dq(N * L, 0.0), dc(N * 3, 0.0);
  object_channels_backward(N, L, lay, objs, q.data(), c.data(), up.data(), dq.data(), dc.data());
  check_grad(q, loss, dq);
  check_grad(c, loss, dc);
}

// The pooled predictions sum over every Gaussian: in fixed chunks of Gaussians added in chunk order, the same bits
// at 1, 2 and 3 threads (a partial per thread, added in thread order, was not), and the sums' values (a double
// reference).
TEST(Scl, PooledPredictionSameBitsAtEveryThreadCount) {
  std::mt19937 rng(8);
  const int N = 5003, D = 16, L = 6, J = 3;  // 5 chunks of at least 1024 Gaussians
  const int objs[J] = {1, 4, 5};
  std::vector<double> qd = randv(size_t(N) * L, rng, 0, 1), fd = randv(size_t(N) * D, rng, -3, 3),
                      ad = randv(size_t(N) * J, rng, 0, 2);
  for (size_t k = 0; k < ad.size(); k += 3) ad[k] = 0;  // Gaussians that miss a mask
  const std::vector<float> q(qd.begin(), qd.end()), f(fd.begin(), fd.end()), a(ad.begin(), ad.end());
  const float mass[J] = {500, 3, 2000};
  std::vector<double> ref(size_t(J) * D, 0.0);
  for (int i = 0; i < N; ++i)
    for (int j = 0; j < J; ++j)
      for (int d = 0; d < D; ++d)
        ref[size_t(j) * D + d] += double(a[size_t(i) * J + j]) * q[size_t(i) * L + objs[j]] * f[size_t(i) * D + d];
  const int threads = omp_get_max_threads();
  std::vector<std::vector<float>> P;
  for (int t : {1, 2, 3}) {
    omp_set_num_threads(t);
    pooled_prediction(N, D, L, J, q.data(), f.data(), a.data(), objs, mass, 1e-6f, P.emplace_back(J * D).data());
  }
  omp_set_num_threads(threads);
  for (int k = 1; k < 3; ++k) EXPECT_EQ(std::memcmp(P[k].data(), P[0].data(), J * D * sizeof(float)), 0) << k + 1;
  for (int j = 0; j < J; ++j)
    for (int d = 0; d < D; ++d)
      EXPECT_NEAR(P[0][size_t(j) * D + d], ref[size_t(j) * D + d] / (mass[j] + 1e-6), 1e-5 * N / mass[j]) << j << d;
}

// Half-precision rows (the trainer's language embeddings) converted in registers as they are added give the bits
// of the rows widened first by ExtraGroup::row, at D = 512 and at a D with a tail of 5 (not a multiple of 8).
TEST(Scl, PooledPredictionHalfIsTheWidenedRowsBitwise) {
  std::mt19937 rng(12);
  for (int D : {512, 13}) {
    const int N = 2600, L = 5, J = 4;  // 3 chunks
    const int objs[J] = {0, 2, 3, 4};
    ExtraGroup f;
    f.dim = D;
    f.f16 = true;
    f.half.resize(size_t(N) * D);
    for (auto& h : f.half) h = float_to_half(std::uniform_real_distribution<float>(-2, 2)(rng));
    std::vector<float> q(size_t(N) * L), a(size_t(N) * J, 0.f);
    for (auto& x : q) x = std::uniform_real_distribution<float>(0, 1)(rng);
    for (int i = 0; i < N; ++i)
      for (int j = 0; j < J; ++j)
        if (rng() % 3 == 0) a[size_t(i) * J + j] = std::uniform_real_distribution<float>(0, 3)(rng);
    const float mass[J] = {40, 7, 900, 1};
    std::vector<float> widened(size_t(J) * D), half(size_t(J) * D);
    pooled_prediction_rows(
        N, D, L, J, q.data(),
        [&](long i, float* buf) -> const float* {
          f.row(size_t(i), buf);
          return buf;
        },
        a.data(), objs, mass, 1e-6f, widened.data());
    pooled_prediction_half(N, D, L, J, q.data(), f.half.data(), a.data(), objs, mass, 1e-6f, half.data());
    EXPECT_EQ(std::memcmp(widened.data(), half.data(), widened.size() * sizeof(float)), 0) << "D " << D;
    EXPECT_NE(widened, std::vector<float>(widened.size(), 0.f));
  }
}

TEST(Scl, PooledPredictionAndInfoNceGradients) {
  std::mt19937 rng(3);
  const int N = 9, D = 6, L = 4, J = 2;
  const int objs[J] = {1, 3};
  std::vector<double> q = randv(N * L, rng, 0, 1), f = randv(N * D, rng), a = randv(N * J, rng, 0, 2);
  a[2 * J] = 0;  // a Gaussian that does not touch object 0's mask
  const double mass[J] = {5, 3};
  std::vector<double> refs = randv(3 * D, rng);
  for (int r = 0; r < 3; ++r) normalize(&refs[r * D], D);
  auto loss = [&] {
    std::vector<double> P(J * D);
    pooled_prediction(N, D, L, J, q.data(), f.data(), a.data(), objs, mass, 1e-6, P.data());
    return info_nce(&P[0], D, refs.data(), 3, 0, 0.2, (double*)nullptr, 1.0) +
           0.5 * info_nce(&P[D], D, refs.data(), 3, 2, 0.2, (double*)nullptr, 1.0);
  };
  std::vector<double> P(J * D), dP(J * D, 0.0);
  pooled_prediction(N, D, L, J, q.data(), f.data(), a.data(), objs, mass, 1e-6, P.data());
  info_nce(&P[0], D, refs.data(), 3, 0, 0.2, &dP[0], 1.0);
  info_nce(&P[D], D, refs.data(), 3, 2, 0.2, &dP[D], 0.5);
  std::vector<double> dq(N * L, 0.0), df(N * D, 0.0), da(N * J);
  pooled_prediction_backward(N, D, L, J, q.data(), f.data(), a.data(), objs, mass, 1e-6, dP.data(), dq.data(),
                             df.data(), da.data());
  check_grad(q, loss, dq);
  check_grad(f, loss, df);
  // da is exact where a != 0; where a = 0 the Gaussian covers no pixel of the mask, the renderer never reads
  // da there and it is documented as 0.
  EXPECT_EQ(da[2 * J], 0.0);
  std::vector<double> a_rest, da_rest;
  for (size_t i = 0; i < a.size(); ++i)
    if (i != size_t(2 * J)) a_rest.push_back(a[i]), da_rest.push_back(da[i]);
  auto loss_rest = [&] {
    for (size_t i = 0, r = 0; i < a.size(); ++i)
      if (i != size_t(2 * J)) a[i] = a_rest[r++];
    return loss();
  };
  check_grad(a_rest, loss_rest, da_rest);
  // The trainer runs the backward one row at a time (pooled_backward_row for dq and da, pooled_df_row for f's
  // row-sparse Adam step): the same dq, da and df, and "no gradient" exactly for a Gaussian that touches no mask.
  std::vector<double> G(J * D);
  for (int j = 0; j < J; ++j)
    for (int d = 0; d < D; ++d) G[j * D + d] = dP[j * D + d] / (mass[j] + 1e-6);
  a[3 * J] = a[3 * J + 1] = 0;
  std::fill(df.begin(), df.end(), 0.0);
  std::fill(dq.begin(), dq.end(), 0.0);
  pooled_prediction_backward(N, D, L, J, q.data(), f.data(), a.data(), objs, mass, 1e-6, dP.data(), dq.data(),
                             df.data(), da.data());
  std::vector<double> dq_rows(N * L, 0.0), da_rows(N * J, -3.0);
  for (int i = 0; i < N; ++i) {
    std::vector<double> row(D, -7.0);
    pooled_backward_row(i, D, L, J, q.data(), f.data() + i * D, a.data(), objs, G.data(), dq_rows.data(),
                        da_rows.data());
    const bool any = pooled_df_row(D, J, q.data() + i * L, a.data() + i * J, objs, G.data(), row.data(), false);
    EXPECT_EQ(any, i != 3) << "row " << i;
    for (int d = 0; d < D; ++d) EXPECT_NEAR(any ? row[d] : 0.0, df[i * D + d], 1e-12) << "row " << i;
  }
  for (int k = 0; k < N * L; ++k) EXPECT_NEAR(dq_rows[k], dq[k], 1e-12) << k;
  for (int k = 0; k < N * J; ++k) EXPECT_NEAR(da_rows[k], da[k], 1e-12) << k;
}

TEST(Scl, InfoNceValue) {
  // Two orthogonal references, anchor along the positive: L = -log(e^{1/t} / (e^{1/t} + e^0)).
  double refs[] = {1, 0, 0, 1};
  double p[] = {3, 0};
  const double t = 0.5;
  EXPECT_NEAR(info_nce(p, 2, refs, 2, 0, t, (double*)nullptr, 1.0), -std::log(std::exp(2.0) / (std::exp(2.0) + 1)),
              1e-12);
}

TEST(Bro, BandOnHandMadeMask) {
  // A 3x3 square in a 9x9 image with a 3x3 element: band = dilation minus erosion = 5x5 ring incl. centre
  // square (erosion of a 3x3 square by 3x3 is its centre pixel only).
  const int H = 9, W = 9;
  std::vector<float> M(H * W, 0.f), A(H * W, 0.f), B(H * W);
  for (int y = 3; y < 6; ++y)
    for (int x = 3; x < 6; ++x) M[y * W + x] = 1;
  boundary_band(A.data(), M.data(), H, W, 3, B.data());
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      bool in5 = x >= 2 && x <= 6 && y >= 2 && y <= 6, centre = x == 4 && y == 4;
      EXPECT_EQ(B[y * W + x], in5 && !centre ? 1.f : 0.f) << x << "," << y;
    }
  // A predicted opacity adds its own band, clipped at 1.
  A[0] = 0.5f;
  boundary_band(A.data(), M.data(), H, W, 3, B.data());
  EXPECT_FLOAT_EQ(B[0], 0.5f);
  EXPECT_FLOAT_EQ(B[1 * W + 1], 0.5f);
  EXPECT_FLOAT_EQ(B[2 * W + 2], 1.f);
}

TEST(Bro, LossGradient) {
  std::mt19937 rng(4);
  const int H = 6, W = 7, C = 3, cs = 4;
  std::vector<double> pred = randv(H * W * cs, rng, 0, 1), gt = randv(H * W * cs, rng, 0, 1);
  std::vector<float> B(H * W);
  for (auto& b : B) b = (rng() % 3) * 0.5f;
  auto loss = [&] { return bro_loss(pred.data(), gt.data(), cs, C, B.data(), H, W, 1e-6, (double*)nullptr, 1.0); };
  std::vector<double> g(H * W * cs, 0.0);
  const double l = bro_loss(pred.data(), gt.data(), cs, C, B.data(), H, W, 1e-6, g.data(), 1.0);
  EXPECT_GT(l, 0);
  for (int i = 0; i < H * W; ++i) EXPECT_EQ(g[i * cs + 3], 0.0);  // the 4th channel is not part of the image
  check_grad(pred, loss, g);
  // Identical differences give zero loss.
  EXPECT_EQ(bro_loss(pred.data(), pred.data(), cs, C, B.data(), H, W, 1e-6, (double*)nullptr, 1.0), 0.0);
}

TEST(Bro, ContiguousPathMatchesStridedAndFiniteDifferences) {
  // cs == C takes the vectorised path: same value and gradient as the generic loop on the same image stored
  // with a padding channel, and its own finite-difference check.
  std::mt19937 rng(8);
  const int H = 5, W = 9, C = 3;
  std::vector<double> pred = randv(H * W * C, rng, 0, 1), gt = randv(H * W * C, rng, 0, 1);
  std::vector<float> B(H * W);
  for (auto& b : B) b = (rng() % 3) * 0.5f;
  std::vector<double> p4(H * W * 4, 0.0), g4(H * W * 4, 0.0), gt4(H * W * 4, 0.0);
  for (int i = 0; i < H * W; ++i)
    for (int c = 0; c < C; ++c) p4[i * 4 + c] = pred[i * C + c], gt4[i * 4 + c] = gt[i * C + c];
  std::vector<double> g(H * W * C, 0.0);
  const double l = bro_loss(pred.data(), gt.data(), C, C, B.data(), H, W, 1e-6, g.data(), 0.7);
  const double l4 = bro_loss(p4.data(), gt4.data(), 4, C, B.data(), H, W, 1e-6, g4.data(), 0.7);
  EXPECT_NEAR(l, l4, 1e-12);
  for (int i = 0; i < H * W; ++i)
    for (int c = 0; c < C; ++c) EXPECT_NEAR(g[i * C + c], g4[i * 4 + c], 1e-12);
  auto loss = [&] { return 0.7 * bro_loss(pred.data(), gt.data(), C, C, B.data(), H, W, 1e-6, (double*)nullptr, 1.0); };
  check_grad(pred, loss, g);
}

TEST(Bro, FiltersMatchBruteForce) {
  std::mt19937 rng(9);
  const int H = 7, W = 11;
  std::vector<float> in(H * W), d(H * W), e(H * W);
  for (auto& v : in) v = float(rng() % 100) / 100.f;
  for (int s : {1, 2, 3, 5, 8}) {
    dilate(in.data(), H, W, s, d.data());
    erode(in.data(), H, W, s, e.data());
    const int r = s / 2, r2 = s - 1 - r;
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        float mx = -1, mn = 2;
        for (int yy = std::max(0, y - r); yy <= std::min(H - 1, y + r2); ++yy)
          for (int xx = std::max(0, x - r); xx <= std::min(W - 1, x + r2); ++xx)
            mx = std::max(mx, in[yy * W + xx]), mn = std::min(mn, in[yy * W + xx]);
        EXPECT_EQ(d[y * W + x], mx) << s << " " << x << "," << y;
        EXPECT_EQ(e[y * W + x], mn) << s << " " << x << "," << y;
      }
  }
}

// The band row by row (BandRows, what the object losses' crops stream) against a brute-force band: from any
// first row (a crop's rows start anywhere), each row of A and M read once and in order, at most s - 1 - s/2 rows
// ahead of the row asked for, and a returned row still valid after the next one is asked for.
TEST(Bro, BandRowsFromAnyRowMatchBruteForce) {
  std::mt19937 rng(21);
  const int H = 13, W = 10;
  std::vector<float> A(H * W), M(H * W);
  for (auto& v : A) v = float(rng() % 100) / 100.f;
  for (auto& v : M) v = rng() % 3 == 0 ? 1.f : 0.f;
  for (int s : {1, 2, 3, 5, 8, 21}) {
    const int r = s / 2, r2 = s - 1 - r;
    std::vector<float> ref(H * W), full(H * W);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        float amx = -1, amn = 2, mmx = -1, mmn = 2;
        for (int yy = std::max(0, y - r); yy <= std::min(H - 1, y + r2); ++yy)
          for (int xx = std::max(0, x - r); xx <= std::min(W - 1, x + r2); ++xx) {
            amx = std::max(amx, A[yy * W + xx]), amn = std::min(amn, A[yy * W + xx]);
            mmx = std::max(mmx, M[yy * W + xx]), mmn = std::min(mmn, M[yy * W + xx]);
          }
        ref[y * W + x] = std::clamp(amx - amn + mmx - mmn, 0.f, 1.f);
      }
    boundary_band(A.data(), M.data(), H, W, s, full.data());
    for (int i = 0; i < H * W; ++i) ASSERT_EQ(full[i], ref[i]) << "kernel " << s << " value " << i;
    for (int first : {0, 1, 4, H - 1}) {
      BandRows rows;
      rows.reset(H, W, s);
      int last_a = -1, last_m = -1, asked = first;
      const BandRows::Row a = [&](int y) {
        EXPECT_EQ(y, last_a < 0 ? std::max(0, first - r) : last_a + 1);
        EXPECT_LE(y, asked + r2);
        last_a = y;
        return &A[y * W];
      };
      const BandRows::Row m = [&](int y) {
        EXPECT_EQ(y, last_m < 0 ? std::max(0, first - r) : last_m + 1);
        last_m = y;
        return &M[y * W];
      };
      const float* prev = nullptr;
      for (int y = first; y < H; ++y) {
        asked = y;
        const float* b = rows.row(y, a, m);
        for (int x = 0; x < W; ++x)
          ASSERT_EQ(b[x], ref[y * W + x]) << "kernel " << s << " from " << first << " row " << y;
        if (prev) {
          for (int x = 0; x < W; ++x) ASSERT_EQ(prev[x], ref[(y - 1) * W + x]) << "kernel " << s << " row " << y - 1;
        }
        prev = b;
      }
    }
  }
}

// BroRows from a middle row (a crop's R starts below the crop's top; the first call's row lacks the pairs with
// the row above it): every later row bitwise bro_parts' on the whole image.
TEST(Bro, BroRowsFromAMiddleRowAreBroPartsBitwise) {
  std::mt19937 rng(23);
  std::uniform_real_distribution<float> U(0, 1);
  const int H = 9, W = 8;
  for (int C : {3, 1, 2}) {
    const int L = W * C;
    std::vector<float> x(H * L), y(H * L), B(H * W), unit(H * L);
    for (auto& v : x) v = U(rng);
    for (auto& v : y) v = U(rng) < 0.5f ? 0.f : U(rng);
    for (auto& v : B) v = U(rng) < 0.3f ? 0.f : U(rng);
    std::vector<double> wsum(H * W), num(H * W);
    bro_parts(x.data(), y.data(), C, B.data(), H, W, wsum.data(), num.data(), unit.data());
    for (int first : {1, 3, H - 2, H - 1}) {
      BroRows<float> rows;
      rows.reset(W, C);
      std::vector<float> u(L, -7.f);
      std::vector<double> ws(W), nm(W);
      for (int r = first; r < H; ++r) {
        const bool next = r + 1 < H;
        rows.row(&x[r * L], &y[r * L], &B[r * W], next ? &x[(r + 1) * L] : nullptr, next ? &y[(r + 1) * L] : nullptr,
                 next ? &B[(r + 1) * W] : nullptr, ws.data(), nm.data(), u.data());
        for (int i = 0; i < W; ++i) {
          ASSERT_EQ(ws[i], wsum[r * W + i]) << "C " << C << " from " << first << " row " << r;
          ASSERT_EQ(nm[i], num[r * W + i]) << "C " << C << " from " << first << " row " << r;
        }
        if (r == first) continue;  // (its unit lacks the pairs with the row above)
        for (int i = 0; i < L; ++i) ASSERT_EQ(u[i], unit[r * L + i]) << "C " << C << " from " << first << " row " << r;
      }
    }
  }
}

TEST(Scl, NoSclCosineLossGradient) {
  std::mt19937 rng(5);
  const size_t P = 7;
  const int D = 5, stride = 9;
  std::vector<double> S = randv(P * stride, rng), R = randv(P * D, rng);
  for (int d = 0; d < D; ++d) S[3 * stride + d] = 0;  // an empty pixel: counts 1, no gradient
  auto loss = [&] { return cosine_loss(S.data(), stride, R.data(), P, D, (double*)nullptr, 1.0); };
  std::vector<double> g(P * stride, 0.0);
  const double l = cosine_loss(S.data(), stride, R.data(), P, D, g.data(), 1.0);
  EXPECT_GT(l, 0);
  for (int d = 0; d < stride; ++d) EXPECT_EQ(g[3 * stride + d], 0.0);
  for (size_t p = 0; p < P; ++p)
    for (int d = D; d < stride; ++d) EXPECT_EQ(g[p * stride + d], 0.0);
  // FD away from the empty pixel (its loss is piecewise constant there).
  std::vector<double> S0 = S;
  std::vector<double> x(S.begin(), S.begin() + 3 * stride);
  auto loss_x = [&] {
    std::copy(x.begin(), x.end(), S.begin());
    return loss();
  };
  std::vector<double> gx(g.begin(), g.begin() + 3 * stride);
  check_grad(x, loss_x, gx);
  S = S0;
  // Parallel vectors give zero loss.
  std::vector<double> A = {1, 2, 3}, B = {2, 4, 6};
  EXPECT_NEAR(cosine_loss(A.data(), 3, B.data(), 1, 3, (double*)nullptr, 1.0), 0.0, 1e-12);
}

TEST(Scl, NoSclCosineLossOnTheGridSampledPerPixelIsTheLossOnTheUpsampledMap) {
  // The no-SCL ablation samples S_ref from the feature grid one pixel at a time (cosine_loss_rows with scene.h's
  // bilinear_pixel): gradient bit for bit that of cosine_loss on upsample_bilinear's map and of the loss written
  // out pixel by pixel, at 1 and 3 threads; a pixel with zero features counts 1 and takes no gradient.
  std::mt19937 rng(8);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  const int gh = 5, gw = 7, H = 13, W = 17, D = 11, stride = 14;
  const size_t P = size_t(H) * W;
  std::vector<float> grid(size_t(gh) * gw * D), S(P * stride);
  for (float& x : grid) x = u(rng);
  for (float& x : S) x = u(rng);
  for (int d = 0; d < D; ++d) S[40 * stride + d] = 0.f;
  const std::vector<float> map = upsample_bilinear(grid.data(), gh, gw, D, H, W);
  auto ref = [&](size_t p, float* buf) {  // as SemanticPass::cosine samples it
    return bilinear_pixel(grid.data(), gh, gw, D, H, W, p, buf);
  };
  std::vector<float> px(D);
  for (size_t p = 0; p < P; ++p) {
    bilinear_pixel(grid.data(), gh, gw, D, H, W, p, px.data());
    ASSERT_EQ(std::memcmp(px.data(), &map[p * D], D * sizeof(float)), 0) << "pixel " << p;
  }
  // The loss written out one pixel at a time (the loops take four pixels together: P = 221 leaves one over).
  std::vector<float> gref(P * stride, 0.5f);
  double lref = 0;
  for (size_t p = 0; p < P; ++p) {
    const float *s = &S[p * stride], *r = &map[p * D];
    double ss = 0, rr = 0, sr = 0;
    for (int d = 0; d < D; ++d) {
      ss += double(s[d]) * s[d];
      rr += double(r[d]) * r[d];
      sr += double(s[d]) * r[d];
    }
    if (ss <= 1e-30 || rr <= 1e-30) {
      lref += 1;
      continue;
    }
    const double ns = std::sqrt(ss), nr = std::sqrt(rr), c = sr / (ns * nr);
    lref += 1 - c;
    for (int d = 0; d < D; ++d)
      gref[p * stride + d] += float(-double(0.7f / float(P)) * (r[d] / (ns * nr) - c * s[d] / ss));
  }
  // In double the gradient shows any change of the sums' order (in float it mostly rounds away).
  std::vector<double> Sd(S.begin(), S.end()), Rd(map.begin(), map.end()), gdref(P * stride, 0.25);
  for (size_t p = 0; p < P; ++p) {
    const double *s = &Sd[p * stride], *r = &Rd[p * D];
    double ss = 0, rr = 0, sr = 0;
    for (int d = 0; d < D; ++d) {
      ss += s[d] * s[d];
      rr += r[d] * r[d];
      sr += s[d] * r[d];
    }
    if (ss <= 1e-30 || rr <= 1e-30) continue;
    const double ns = std::sqrt(ss), nr = std::sqrt(rr), c = sr / (ns * nr);
    for (int d = 0; d < D; ++d) gdref[p * stride + d] += -(0.7 / double(P)) * (r[d] / (ns * nr) - c * s[d] / ss);
  }
  const int before = omp_get_max_threads();
  for (int threads : {1, 3}) {
    omp_set_num_threads(threads);
    std::vector<double> gd(P * stride, 0.25);
    cosine_loss(Sd.data(), stride, Rd.data(), P, D, gd.data(), 0.7);
    EXPECT_EQ(gd, gdref) << threads << " threads, double";
    std::vector<float> g0(P * stride, 0.5f), g1 = g0;
    const float l0 = cosine_loss(S.data(), stride, map.data(), P, D, g0.data(), 0.7f);
    const float l1 = cosine_loss_rows(S.data(), stride, ref, P, D, g1.data(), 0.7f);
    // The threads' partial sums meet in any order: the loss to 1e-6.
    EXPECT_NEAR(l1, l0, 1e-6f * l0) << threads << " threads";
    EXPECT_NEAR(l0, float(lref / double(P)), 1e-6f * l0) << threads << " threads";
    EXPECT_GT(l0, 0.f);
    EXPECT_EQ(g0, gref) << threads << " threads";
    EXPECT_EQ(g1, g0) << threads << " threads";
    for (int d = 0; d < stride; ++d) EXPECT_EQ(g1[40 * stride + d], 0.5f);
  }
  omp_set_num_threads(before);
}

TEST(Bro, ScaleInvariantGradientIsTheGradientAtAFixedNorm) {
  // remove_scale_component(p, g) is the exact gradient of L(p * c / ||p||) at p with c = ||p|| held constant
  // (hybrid/bro.h); the loss value there is eq. 14 unchanged.
  std::mt19937 rng(12);
  const int H = 6, W = 8, C = 3;
  std::vector<double> pred = randv(H * W * C, rng, 0, 1), gt = randv(H * W * C, rng, 0, 1);
  std::vector<float> B(H * W);
  for (auto& b : B) b = (rng() % 3) * 0.5f;
  const size_t n = pred.size();
  double c = 0;
  for (double v : pred) c += v * v;
  c = std::sqrt(c);
  auto loss = [&] {
    double nrm = 0;
    for (double v : pred) nrm += v * v;
    std::vector<double> p(n);
    for (size_t i = 0; i < n; ++i) p[i] = pred[i] * c / std::sqrt(nrm);
    return bro_loss(p.data(), gt.data(), C, C, B.data(), H, W, 1e-6, (double*)nullptr, 1.0);
  };
  std::vector<double> g(n, 0.0);
  const double l = bro_loss(pred.data(), gt.data(), C, C, B.data(), H, W, 1e-6, g.data(), 1.0);
  EXPECT_NEAR(loss(), l, 1e-12);
  remove_scale_component(pred.data(), n, g.data());
  double gp = 0;
  for (size_t i = 0; i < n; ++i) gp += g[i] * pred[i];
  EXPECT_NEAR(gp, 0.0, 1e-12);  // no first-order change when the whole render is scaled
  check_grad(pred, loss, g);
  // A zero render has no scale direction: the gradient is left as it is.
  std::vector<double> zero(n, 0.0), g2(n, 1.0);
  remove_scale_component(zero.data(), n, g2.data());
  for (double v : g2) EXPECT_EQ(v, 1.0);
}

TEST(Bro, PlainGradientFadesAnObjectWhoseMaskEdgeIsMisaligned) {
  // The failure the scale-invariant gradient removes (hybrid/bro.h): an object rendered as a 6x6 square of
  // value 0.8 against a view mask eroded by one pixel on every side (the image inside the mask is the same
  // 0.8). Eq. 14's own gradient points towards a fainter object (<g, p> > 0: gradient descent lowers the
  // render as a whole); the scale-invariant gradient has no such component and still moves the edges.
  const int H = 12, W = 12, C = 3;
  std::vector<double> pred(H * W * C, 0.0), gt(H * W * C, 0.0);
  std::vector<float> A(H * W, 0.f), M(H * W, 0.f), B(H * W);
  for (int y = 3; y < 9; ++y)
    for (int x = 3; x < 9; ++x) {
      A[y * W + x] = 1.f;
      const bool in_mask = y >= 4 && y < 8 && x >= 4 && x < 8;
      M[y * W + x] = in_mask ? 1.f : 0.f;
      for (int c = 0; c < C; ++c) {
        pred[(y * W + x) * C + c] = 0.8;
        gt[(y * W + x) * C + c] = in_mask ? 0.8 : 0.0;
      }
    }
  boundary_band(A.data(), M.data(), H, W, 5, B.data());
  std::vector<double> g(pred.size(), 0.0);
  bro_loss(pred.data(), gt.data(), C, C, B.data(), H, W, 1e-6, g.data(), 1.0);
  double gp = 0;
  for (size_t i = 0; i < g.size(); ++i) gp += g[i] * pred[i];
  EXPECT_GT(gp, 0.0) << "eq. 14's gradient should favour fading on a misaligned mask";
  // Fading the render lowers eq. 14 here (the failure mode measured on trained models).
  std::vector<double> half = pred;
  for (auto& v : half) v *= 0.5;
  EXPECT_LT(bro_loss(half.data(), gt.data(), C, C, B.data(), H, W, 1e-6, (double*)nullptr, 1.0),
            bro_loss(pred.data(), gt.data(), C, C, B.data(), H, W, 1e-6, (double*)nullptr, 1.0));
  remove_scale_component(pred.data(), pred.size(), g.data());
  gp = 0;
  double norm = 0;
  for (size_t i = 0; i < g.size(); ++i) gp += g[i] * pred[i], norm += g[i] * g[i];
  EXPECT_NEAR(gp, 0.0, 1e-12);
  EXPECT_GT(norm, 1e-6);  // the edges still get a gradient
}
