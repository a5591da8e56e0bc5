// End-to-end gradient checks of the hybrid objective through the double-precision renderer:
//  - object-conditioned appearance loss (eq. 6) + BRO (eq. 14, band held constant) to the view logits (through
//    q and Observation Fusion) and to the colours;
//  - SCL (eqs. 9-10) through the rasterizer's pixel-weighted sums to the opacities, f and q;
//  - the pooling identity: pooled semantic render == sum_n q f a / (m + eps).
// Only coordinates that move no discrete rasterizer decision are perturbed (logits, colours, f, q), or tiny
// steps on opacities far from the cut-offs.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

#include "fd_check.h"
#include "hybrid/bro.h"
#include "hybrid/fusion.h"
#include "hybrid/object_channels.h"
#include "hybrid/scl.h"
#include "render/renderer.h"
#include "train/loss.h"
#include "train/ssim.h"

using namespace hgs;
using namespace hgs::hybrid;

namespace {

struct Scene {
  int W = 40, H = 30, N = 36, L = 3, U = 5;
  render::Camera cam;
  std::vector<double> mean, log_scale, quat, opacity, colors;
  LabelMap labels;
  std::vector<double> gt;  // [H, W, 3]
  ObservationTable tab;

  Scene() {
    std::mt19937 rng(11);
    std::uniform_real_distribution<double> u(0, 1);
    cam.width = W;
    cam.height = H;
    cam.fx = cam.fy = 40;
    cam.cx = 20;
    cam.cy = 15;
    for (int i = 0; i < N; ++i) {
      mean.insert(mean.end(), {u(rng) * 1.6 - 0.8, u(rng) * 1.2 - 0.6, 2 + u(rng)});
      const double s = std::log(0.08 + 0.1 * u(rng));
      log_scale.insert(log_scale.end(), {s, s + 0.3 * (u(rng) - 0.5), s});
      quat.insert(quat.end(), {1, 0.2 * (u(rng) - 0.5), 0.2 * (u(rng) - 0.5), 0.1});
      opacity.push_back(u(rng) * 2 - 1);
      colors.insert(colors.end(), {u(rng), u(rng), u(rng)});
    }
    labels = LabelMap(W, H);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) labels.at(x, y) = x < 14 ? 0 : (y < 15 ? 1 : 2);
    for (int i = 0; i < W * H * 3; ++i) gt.push_back(u(rng));
    tab.n = N;
    tab.num_views = U;
    for (int i = 0; i < N * U; ++i) tab.label.push_back(rng() % 6 == 0 ? kNoObservation : uint16_t(rng() % L));
  }

  render::GaussianInputsT<double> inputs() const {
    render::GaussianInputsT<double> in;
    in.n = N;
    in.mean = mean.data();
    in.log_scale = log_scale.data();
    in.quat = quat.data();
    in.opacity_logit = opacity.data();
    in.colors = colors.data();
    return in;
  }
};

// Central differences within rtol of max(|fd|, |analytic|) plus 1e-7 of the largest |analytic|; more than a
// quarter of the differences must exceed 1e-9 for the check to mean something.
void check(const char* name, std::vector<double>& x, const std::function<double()>& f, const std::vector<double>& an,
           double h = 1e-6, double rtol = 1e-5) {
  const test::FdStats st =
      test::fd_check(name, x, test::all_indices(x.size()), an, f,
                     {.h = h, .rtol = rtol, .scale_atol = 1e-7, .noise_atol = 0, .nonzero_fd = 1e-9});
  EXPECT_GT(st.nonzero, int(x.size()) / 4) << name << ": too few non-zero gradients to be a meaningful check";
}

}  // namespace

TEST(HybridRender, ObjectConditionedLossToViewLogitsAndColours) {
  Scene sc;
  const int HW = sc.W * sc.H;
  const std::vector<int> objs = {0, 1, 2};
  const int J = 3;
  const ObjectLayout lay{J, 0};
  const int C = lay.total();
  std::mt19937 rng(3);
  std::vector<double> logits(sc.U);
  for (auto& l : logits) l = std::uniform_real_distribution<double>(-1, 1)(rng);
  FusionParams fp{sc.L, 0.25, 1e-6};
  std::vector<double> q0(sc.N * sc.L, 1.0 / 3);
  std::vector<float> bands;  // fixed at the base point (B is a constant of the loss)

  // Returns the loss; with grads it fills dlogits and dcolors.
  auto run = [&](std::vector<double>* dlogits, std::vector<double>* dcolors) {
    std::vector<double> w(sc.U), q = q0, s(sc.N * sc.L), extra(sc.N * C);
    std::vector<uint8_t> valid(sc.N);
    softmax(logits.data(), sc.U, w.data());
    fuse(sc.tab, w.data(), fp, q.data(), s.data(), valid.data());
    object_channels(sc.N, sc.L, lay, objs.data(), q.data(), sc.colors.data(), extra.data());
    render::RendererT<double> r;
    auto in = sc.inputs();
    in.extra = extra.data();
    in.num_extra = C;
    render::RenderSettings rs;
    rs.want_depth = false;
    render::RenderOutputsT<double> out;
    r.forward(sc.cam, in, rs, out);
    if (bands.empty()) {
      bands.resize(size_t(J) * HW);
      std::vector<float> A(HW), M(HW);
      for (int j = 0; j < J; ++j) {
        for (int p = 0; p < HW; ++p) {
          A[p] = float(out.extra[p * C + lay.opacity(j)]);
          M[p] = sc.labels.v[p] == objs[j];
        }
        boundary_band(A.data(), M.data(), sc.H, sc.W, 5, &bands[size_t(j) * HW]);
      }
    }
    std::vector<double> d_extra(size_t(HW) * C, 0.0), pred(HW * 3), gtm(HW * 3), g(HW * 3), gs(HW * 3);
    train::SsimWorkspace<double> ws;
    double loss = 0;
    for (int j = 0; j < J; ++j) {
      for (int p = 0; p < HW; ++p)
        for (int c = 0; c < 3; ++c) {
          pred[p * 3 + c] = out.extra[p * C + lay.color(j) + c];
          gtm[p * 3 + c] = sc.gt[p * 3 + c] * (sc.labels.v[p] == objs[j]);
        }
      std::fill(g.begin(), g.end(), 0.0);
      const double l1 = train::l1_loss(pred.data(), gtm.data(), pred.size(), g.data(), 0.8 / J);
      const double ss = train::ssim(pred.data(), gtm.data(), sc.H, sc.W, 3, gs.data(), ws);
      for (int i = 0; i < HW * 3; ++i) g[i] -= 0.2 / J * gs[i];
      const double bro =
          bro_loss(pred.data(), gtm.data(), 3, 3, &bands[size_t(j) * HW], sc.H, sc.W, 1e-6, g.data(), 1.0 / J);
      loss += (0.8 * l1 + 0.2 * (1 - ss) + bro) / J;
      for (int p = 0; p < HW; ++p)
        for (int c = 0; c < 3; ++c) d_extra[p * C + lay.color(j) + c] = g[p * 3 + c];
    }
    if (dlogits) {
      render::OutputGradsT<double> dout;
      dout.extra = d_extra.data();
      dout.extra_grad_channels = lay.grad_channels();  // the opacities feed only the (constant) bands
      render::GaussianGradsT<double> grads;
      r.backward(dout, grads);
      std::vector<double> dq(sc.N * sc.L, 0.0), dw(sc.U);
      *dcolors = grads.colors;
      object_channels_backward(sc.N, sc.L, lay, objs.data(), q.data(), sc.colors.data(), grads.extra.data(), dq.data(),
                               dcolors->data());
      fuse_backward(sc.tab, w.data(), fp, s.data(), q.data(), valid.data(), dq.data(), dw.data());
      dlogits->resize(sc.U);
      softmax_backward(w.data(), dw.data(), sc.U, dlogits->data());
    }
    return loss;
  };
  std::vector<double> dlogits, dcolors;
  run(&dlogits, &dcolors);
  check(
      "view logits", logits, [&] { return run(nullptr, nullptr); }, dlogits);
  check(
      "colours", sc.colors, [&] { return run(nullptr, nullptr); }, dcolors);
}

TEST(HybridRender, PoolingIdentityMatchesDirectSemanticRender) {
  Scene sc;
  const int HW = sc.W * sc.H, D = 6;
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> q(sc.N * sc.L), f(sc.N * D);
  for (auto& x : q) x = 0.5 + 0.5 * u(rng);
  for (auto& x : f) x = u(rng);
  const int objs[2] = {1, 2};
  std::vector<float> M(size_t(HW) * 2);
  std::vector<double> mass = {0, 0};
  for (int p = 0; p < HW; ++p)  // planar [2, H, W]
    for (int j = 0; j < 2; ++j) {
      M[size_t(j) * HW + p] = sc.labels.v[p] == objs[j];
      mass[j] += M[size_t(j) * HW + p];
    }
  // Identity side: a from the rasterizer's pixel-weighted sums.
  render::RendererT<double> r;
  auto in = sc.inputs();
  render::RenderSettings rs;
  rs.want_depth = false;
  rs.pixel_weights = M.data();
  rs.num_pixel_weights = 2;
  render::RenderOutputsT<double> out;
  r.forward(sc.cam, in, rs, out);
  std::vector<double> P(2 * D);
  pooled_prediction(sc.N, D, sc.L, 2, q.data(), f.data(), out.weight_sums.data(), objs, mass.data(), 1e-6, P.data());
  // Direct side: render S_k = sum q_k f alpha T as D channels per object, then pool with the mask (eq. 9).
  for (int j = 0; j < 2; ++j) {
    std::vector<double> ch(sc.N * D);
    for (int i = 0; i < sc.N; ++i)
      for (int d = 0; d < D; ++d) ch[i * D + d] = q[i * sc.L + objs[j]] * f[i * D + d];
    auto in2 = sc.inputs();
    in2.extra = ch.data();
    in2.num_extra = D;
    render::RenderSettings rs2;
    rs2.want_depth = false;
    render::RenderOutputsT<double> o2;
    render::RendererT<double> r2;
    r2.forward(sc.cam, in2, rs2, o2);
    for (int d = 0; d < D; ++d) {
      double acc = 0;
      for (int p = 0; p < HW; ++p) acc += M[size_t(j) * HW + p] * o2.extra[p * D + d];
      const double direct = acc / (mass[j] + 1e-6);
      EXPECT_NEAR(P[j * D + d], direct, 1e-12 + 1e-10 * std::abs(direct)) << "object " << objs[j] << " dim " << d;
    }
  }
  double norm = 0;
  for (double x : P) norm += x * x;
  EXPECT_GT(norm, 1e-6);  // the objects are actually covered
}

TEST(HybridRender, SemanticContrastiveToOpacityFAndQ) {
  Scene sc;
  const int HW = sc.W * sc.H, D = 5;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> u(-1, 1);
  std::vector<double> q(sc.N * sc.L), f(sc.N * D), refs(3 * D);
  for (auto& x : q) x = 0.5 + 0.5 * u(rng);
  for (auto& x : f) x = u(rng);
  for (auto& x : refs) x = u(rng);
  for (int k = 0; k < 3; ++k) normalize(&refs[k * D], D);
  const int objs[2] = {1, 2};
  std::vector<float> M(size_t(HW) * 2);
  std::vector<double> mass = {0, 0};
  for (int p = 0; p < HW; ++p)  // planar [2, H, W]
    for (int j = 0; j < 2; ++j) {
      M[size_t(j) * HW + p] = sc.labels.v[p] == objs[j];
      mass[j] += M[size_t(j) * HW + p];
    }
  auto run = [&](std::vector<double>* dop, std::vector<double>* df, std::vector<double>* dq) {
    render::RendererT<double> r;
    auto in = sc.inputs();
    render::RenderSettings rs;
    rs.want_depth = false;
    rs.pixel_weights = M.data();
    rs.num_pixel_weights = 2;
    render::RenderOutputsT<double> out;
    r.forward(sc.cam, in, rs, out);
    std::vector<double> P(2 * D), dP(2 * D, 0.0);
    pooled_prediction(sc.N, D, sc.L, 2, q.data(), f.data(), out.weight_sums.data(), objs, mass.data(), 1e-6, P.data());
    // L = 0.5 InfoNCE(object 1, positive 1) + 0.5 InfoNCE(object 2, positive 2); info_nce returns the
    // unscaled loss and puts scale * dL/dP into dP.
    const double loss = 0.5 * info_nce(&P[0], D, refs.data(), 3, 1, 0.2, &dP[0], 0.5) +
                        0.5 * info_nce(&P[D], D, refs.data(), 3, 2, 0.2, &dP[D], 0.5);
    if (dop) {
      std::vector<double> da(sc.N * 2);
      dq->assign(sc.N * sc.L, 0.0);
      df->assign(sc.N * D, 0.0);
      pooled_prediction_backward(sc.N, D, sc.L, 2, q.data(), f.data(), out.weight_sums.data(), objs, mass.data(), 1e-6,
                                 dP.data(), dq->data(), df->data(), da.data());
      render::OutputGradsT<double> dout;
      dout.weight_sums = da.data();
      render::GaussianGradsT<double> grads;
      r.backward(dout, grads);
      *dop = grads.opacity_logit;
    }
    return loss;
  };
  std::vector<double> dop, df, dq;
  const double l0 = run(&dop, &df, &dq);
  EXPECT_GT(l0, 0);
  auto loss = [&] { return run(nullptr, nullptr, nullptr); };
  check("f", f, loss, df);
  check("q", q, loss, dq);
  check("opacity logits", sc.opacity, loss, dop, 1e-6, 1e-4);
}
