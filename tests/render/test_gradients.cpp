// Finite-difference gradient checks in double precision for every stage of the renderer (projection, SH,
// compositing of RGB/alpha/depth/extra channels, the full pipeline end to end, the 2D-mean statistic), plus
// float-vs-double agreement of the production path and bitwise determinism.
//
// Discontinuities (alpha = 1/255 skip, 0.99 clamp, T < 1e-4 stop, near-plane culling, the 1.3x FOV clamp, the SH
// clamp at 0, integer radii / tile rects): scenes are random, so instead of hoping to avoid them every +-h
// evaluation is paired with the reference renderer's decision signature and coordinates whose perturbation flips
// any decision are skipped (tests/fd_check.h); at most 10% may be skipped. The x/y clamp, SH clamp, near-plane and
// behind-camera Gaussians, tile-border overlap and the T cut-off are all present in these scenes (asserted).
#include <gtest/gtest.h>
#include <omp.h>

#include <cstdint>
#include <cstring>
#include <type_traits>

#include "core/error.h"
#include "fd_check.h"
#include "render/binning.h"
#include "render/project.h"
#include "render/rasterize.h"
#include "render/renderer.h"
#include "render/sh.h"
#include "render_ref.h"
#include "render_run.h"

namespace hgs::render::test {
namespace {

using namespace hgs::test;

// ---------------------------------------------------------------------------------------------------------
TEST(RenderGrad, ProjectionFiniteDifferences) {
  Scene s = random_scene(80, 40, 36, 7);
  const CameraT<double> cam = make_camera<double>(s.cam);
  std::mt19937 rng(3);
  int tested = 0, clamped = 0;
  for (int i = 0; i < s.n; ++i) {
    std::vector<double> p(10);
    for (int k = 0; k < 3; ++k) p[k] = s.mean[3 * i + k], p[3 + k] = s.log_scale[3 * i + k];
    for (int k = 0; k < 4; ++k) p[6 + k] = s.quat[4 * i + k];
    ProjectionTrace<double> tr;
    if (!project_one(cam, &p[0], &p[3], &p[6], tr)) continue;
    ++tested;
    clamped += !tr.inx || !tr.iny;
    const std::vector<double> w = random_weights(6, rng);
    // conic entries are ~1/px^2: scale their weights so every output matters
    const double wc[3] = {w[2] * 100, w[3] * 100, w[4] * 100};
    auto eval = [&]() {
      ProjectionTrace<double> t;
      Eval e;
      const bool vis = project_one(cam, &p[0], &p[3], &p[6], t);
      e.signature = {vis, t.inx, t.iny};
      e.loss = w[0] * t.mean2d[0] + w[1] * t.mean2d[1] + wc[0] * t.conic[0] + wc[1] * t.conic[1] + wc[2] * t.conic[2] +
               w[5] * t.tc[2];
      return e;
    };
    std::vector<double> an(10);
    project_one_backward(cam, tr, &w[0], wc, w[5], &an[0], &an[3], &an[6]);
    fd_check("projection g" + std::to_string(i), p, all_indices(10), an, eval, {.rtol = 1e-6});
  }
  EXPECT_GT(tested, 50);
  EXPECT_GT(clamped, 3);  // the clamped-Jacobian branch is exercised
}

TEST(RenderGrad, ShFiniteDifferences) {
  std::mt19937 rng(5);
  std::normal_distribution<double> N01(0, 1);
  int clamped = 0;
  for (int deg = 0; deg <= 3; ++deg) {
    for (int trial = 0; trial < 12; ++trial) {
      std::vector<double> p(16 * 3 + 3);  // sh [16, 3] then mean [3]
      for (int k = 0; k < 48; ++k) p[k] = (k < 3 ? 0.8 : 0.3) * N01(rng);
      for (int k = 0; k < 3; ++k) p[48 + k] = N01(rng);
      const double campos[3] = {0.1, -0.2, 0.3};
      const std::vector<double> w = random_weights(3, rng);
      auto eval = [&]() {
        const double dir[3] = {p[48] - campos[0], p[49] - campos[1], p[50] - campos[2]};
        double col[3], raw[3];
        sh_eval_one(deg, p.data(), dir, col, raw);
        Eval e;
        e.signature = {raw[0] > 0, raw[1] > 0, raw[2] > 0};
        e.loss = w[0] * col[0] + w[1] * col[1] + w[2] * col[2];
        return e;
      };
      std::vector<double> an(51, 0.0);
      const double dir[3] = {p[48] - campos[0], p[49] - campos[1], p[50] - campos[2]};
      sh_backward_one(deg, p.data(), dir, w.data(), an.data(), &an[48]);
      const Eval e0 = eval();
      clamped += 3 - (e0.signature[0] + e0.signature[1] + e0.signature[2]);
      std::vector<int> idx;
      for (int k = 0; k < 3 * sh_num_coeffs(deg); ++k) idx.push_back(k);
      if (deg > 0) idx.insert(idx.end(), {48, 49, 50});
      fd_check("sh deg " + std::to_string(deg), p, idx, an, eval, {.rtol = 1e-7});
    }
  }
  EXPECT_GT(clamped, 0);
}

// ---------------------------------------------------------------------------------------------------------
// Rasterizer alone on 2D inputs.
struct Raster2D {
  const Scene* s;
  int n, C;
  std::vector<double> mean2d, conic, opacity, color, depth, extra;
  std::vector<int> radius;
  Binning bins;
  RasterWorkspace<double> ws;
  std::vector<double> rgb, alpha, dep, ext, finalT, wsum;
  std::vector<int32_t> last;

  RasterInputs<double> inputs() const {
    RasterInputs<double> in;
    in.width = s->cam.width;
    in.height = s->cam.height;
    in.n = n;
    in.mean2d = mean2d.data();
    in.conic = conic.data();
    in.opacity = opacity.data();
    in.color = color.data();
    in.depth = depth.data();
    in.extra = C ? extra.data() : nullptr;
    in.num_extra = C;
    for (int k = 0; k < 3; ++k) in.background[k] = s->settings.background[k];
    in.pixel_weights = s->num_weights ? s->pixel_weights.data() : nullptr;
    in.num_weights = s->num_weights;
    return in;
  }
  void forward() {
    const int W = s->cam.width, H = s->cam.height;
    bin_gaussians<double>(W, H, n, mean2d.data(), conic.data(), opacity.data(), depth.data(), radius.data(), bins);
    rgb.resize(size_t(W) * H * 3);
    alpha.resize(size_t(W) * H);
    dep.resize(size_t(W) * H);
    ext.resize(size_t(W) * H * C);
    finalT.resize(size_t(W) * H);
    last.resize(size_t(W) * H);
    wsum.resize(size_t(n) * s->num_weights);
    RasterOutputs<double> o;
    o.weight_sums = wsum.data();
    o.rgb = rgb.data();
    o.alpha = alpha.data();
    o.depth = dep.data();
    o.extra = ext.data();
    o.final_T = finalT.data();
    o.last = last.data();
    rasterize_forward(inputs(), bins, ws, o);
  }
  // Reference signature for the current 2D parameters.
  std::vector<int> signature() const {
    std::vector<RefProjected> P(n);
    for (int i = 0; i < n; ++i) {
      RefProjected& p = P[i];
      p.visible = radius[i] > 0;
      p.u = mean2d[2 * i], p.v = mean2d[2 * i + 1];
      for (int k = 0; k < 3; ++k) p.conic[k] = conic[3 * i + k], p.color[k] = color[3 * i + k];
      p.opacity = opacity[i];
      p.depth = depth[i];
      p.radius = radius[i];
      const int r = radius[i], W = s->cam.width, H = s->cam.height;
      p.tx0 = std::max(0, int(std::ceil(p.u - r - 0.5))) / 16;
      p.tx1 = std::min(W - 1, int(std::floor(p.u + r - 0.5))) / 16;
      p.ty0 = std::max(0, int(std::ceil(p.v - r - 0.5))) / 16;
      p.ty1 = std::min(H - 1, int(std::floor(p.v + r - 0.5))) / 16;
    }
    return ref_composite(*s, P).signature;
  }
};

TEST(RenderGrad, RasterizeFiniteDifferences) {
  SingleThread one_thread;
  for (uint32_t seed : {21u, 22u}) {
    Scene s = random_scene(45, 40, 36, seed, 0.9, 2);
    s.add_pixel_weights(2, seed);
    const auto P = ref_project(s);
    Raster2D r;
    r.s = &s;
    r.n = s.n;
    r.C = s.num_extra;
    for (int i = 0; i < s.n; ++i) {
      r.mean2d.insert(r.mean2d.end(), {P[i].u, P[i].v});
      r.conic.insert(r.conic.end(), {P[i].conic[0], P[i].conic[1], P[i].conic[2]});
      r.opacity.push_back(P[i].opacity);
      r.color.insert(r.color.end(), {P[i].color[0], P[i].color[1], P[i].color[2]});
      r.depth.push_back(P[i].depth);
      r.radius.push_back(P[i].visible ? P[i].radius : 0);
    }
    r.extra = s.extra;
    std::mt19937 rng(seed);
    const std::vector<double> wr = random_weights(r.rgb.size() + 40 * 36 * 3, rng);
    const std::vector<double> wa = random_weights(40 * 36, rng), wd = random_weights(40 * 36, rng);
    const std::vector<double> we = random_weights(40 * 36 * r.C, rng);
    const std::vector<double> ww = random_weights(size_t(r.n) * s.num_weights, rng);
    auto eval = [&]() {
      r.forward();
      Eval e;
      e.loss = dot(wr, r.rgb) + dot(wa, r.alpha) + dot(wd, r.dep) + dot(we, r.ext) + dot(ww, r.wsum);
      e.signature = r.signature();
      return e;
    };
    eval();
    RasterGrads<double> g;
    std::vector<double> gm(2 * r.n), gc(3 * r.n), go(r.n), gcol(3 * r.n), gd(r.n), ge(r.n * r.C);
    g.d_rgb = wr.data();
    g.d_alpha = wa.data();
    g.d_depth = wd.data();
    g.d_extra = we.data();
    g.d_weight_sums = ww.data();
    g.mean2d = gm.data();
    g.conic = gc.data();
    g.opacity = go.data();
    g.color = gcol.data();
    g.depth = gd.data();
    g.extra = ge.data();
    rasterize_backward(r.inputs(), r.bins, r.ws, r.finalT.data(), r.last.data(), g);
    fd_check("raster mean2d", r.mean2d, all_indices(r.mean2d.size()), gm, eval);
    fd_check("raster conic", r.conic, all_indices(r.conic.size()), gc, eval, {.h = 1e-7});
    fd_check("raster opacity", r.opacity, all_indices(r.opacity.size()), go, eval);
    fd_check("raster color", r.color, all_indices(r.color.size()), gcol, eval);
    fd_check("raster depth", r.depth, all_indices(r.depth.size()), gd, eval);
    fd_check("raster extra", r.extra, all_indices(r.extra.size()), ge, eval);
  }
}

// ---------------------------------------------------------------------------------------------------------
// Full pipeline.
struct EndToEnd {
  Scene s;
  std::vector<double> wr, wa, wd, we, ww;
  RendererT<double> r;
  RenderOutputsT<double> out;
  std::vector<std::vector<double>> store;

  explicit EndToEnd(const Scene& sc, uint32_t seed) : s(sc) {
    std::mt19937 rng(seed);
    const size_t P = size_t(s.cam.width) * s.cam.height;
    wr = random_weights(3 * P, rng);
    wa = random_weights(P, rng);
    wd = random_weights(P, rng);
    we = random_weights(P * s.num_extra, rng);
    ww = random_weights(size_t(s.n) * s.num_weights, rng);
    if (s.num_weights) s.settings.pixel_weights = s.pixel_weights.data();  // point at this copy
  }
  double loss() {
    return dot(wr, out.rgb) + dot(wa, out.alpha) + dot(wd, out.depth) + dot(we, out.extra) + dot(ww, out.weight_sums);
  }
  Eval eval() {
    r.forward(s.cam, s.inputs<double>(store), s.settings, out);
    Eval e;
    e.loss = loss();
    e.signature = ref_render(s).signature;
    return e;
  }
  // Backward of loss(); extra_grad_channels >= 0 makes the extra channels past it forward-only.
  GaussianGradsT<double> grads(int extra_grad_channels = -1) {
    eval();
    GaussianGradsT<double> g;
    OutputGradsT<double> d;
    d.rgb = wr.data();
    d.alpha = wa.data();
    d.depth = wd.data();
    d.extra = s.num_extra ? we.data() : nullptr;
    d.weight_sums = s.num_weights ? ww.data() : nullptr;
    d.extra_grad_channels = extra_grad_channels;
    r.backward(d, g);
    return g;
  }
};

TEST(RenderGrad, EndToEndShFiniteDifferences) {
  SingleThread one_thread;
  Scene sc = random_scene(50, 40, 36, 31, 0.9, 2);
  {  // the scene covers the cases the comment above promises
    const auto P = ref_project(sc);
    const RefImage img = ref_composite(sc, P);
    int cx = 0, near = 0, behind = 0, multi_tile = 0, shc = 0;
    for (int i = 0; i < sc.n; ++i) {
      cx += P[i].visible && (P[i].clampx || P[i].clampy);
      multi_tile += P[i].visible && (P[i].tx1 > P[i].tx0 || P[i].ty1 > P[i].ty0);
      shc += P[i].visible && P[i].sh_clamped;
      const double* m = &sc.mean[3 * i];
      const double z = sc.cam.R[6] * m[0] + sc.cam.R[7] * m[1] + sc.cam.R[8] * m[2] + sc.cam.t[2];
      near += z > 0.2 && z < 0.8 && P[i].visible;
      behind += z < 0;
    }
    EXPECT_GT(cx, 0);
    EXPECT_GT(near, 0);
    EXPECT_GT(behind, 0);
    EXPECT_GT(multi_tile, 5);
    EXPECT_GT(shc, 0);
  }
  EndToEnd e(sc, 4);
  const GaussianGradsT<double> g = e.grads();
  auto ev = [&]() { return e.eval(); };
  fd_check("e2e mean", e.s.mean, all_indices(e.s.mean.size()), g.mean, ev);
  fd_check("e2e log_scale", e.s.log_scale, all_indices(e.s.log_scale.size()), g.log_scale, ev);
  fd_check("e2e quat", e.s.quat, all_indices(e.s.quat.size()), g.quat, ev);
  fd_check("e2e opacity_logit", e.s.opacity_logit, all_indices(e.s.opacity_logit.size()), g.opacity_logit, ev);
  std::vector<int> idx;
  for (size_t k = 0; k < e.s.sh.size(); k += 7) idx.push_back(int(k));
  fd_check("e2e sh", e.s.sh, idx, g.sh, ev);
  fd_check("e2e extra", e.s.extra, all_indices(e.s.extra.size()), g.extra, ev);
  EXPECT_TRUE(g.colors.empty());
}

TEST(RenderGrad, EndToEndColoursNoDepthFiniteDifferences) {
  SingleThread one_thread;
  Scene sc = random_scene(40, 40, 36, 41, 0.9, 3);
  sc.add_pixel_weights(3, 41);  // per-mask blending-weight sums (SCL pooling) are differentiated too
  sc.use_colors = true;
  sc.settings.want_depth = false;
  EndToEnd e(sc, 5);
  e.wd.clear();
  const GaussianGradsT<double> g = e.grads();
  EXPECT_TRUE(g.sh.empty());  // random_scene inputs pass no SH when colours are used
  auto ev = [&]() { return e.eval(); };
  fd_check("e2e colors", e.s.colors, all_indices(e.s.colors.size()), g.colors, ev);
  fd_check("e2e extra", e.s.extra, all_indices(e.s.extra.size()), g.extra, ev);
  fd_check("e2e mean", e.s.mean, all_indices(e.s.mean.size()), g.mean, ev);
  fd_check("e2e opacity_logit", e.s.opacity_logit, all_indices(e.s.opacity_logit.size()), g.opacity_logit, ev);
}

// The hybrid method's case: many extra channels (29: the register chunks of 12, 12, 4 and 1), hard label masks
// as pixel weights (most batches see one map) and a forward-only tail (extra_grad_channels = 25).
TEST(RenderGrad, ManyChannelsHardMasksFiniteDifferences) {
  SingleThread one_thread;
  Scene sc = random_scene(30, 43, 36, 61, 0.9, 29);  // 43 wide: the last batch of each row has 3 pixels
  sc.add_label_weights(4, 5);
  sc.use_colors = true;
  sc.settings.want_depth = false;
  EndToEnd e(sc, 7);
  e.wd.clear();
  const size_t P = size_t(sc.cam.width) * sc.cam.height;
  for (size_t p = 0; p < P; ++p)
    for (int c = 25; c < 29; ++c) e.we[p * 29 + c] = 0;  // what the loss sees of the forward-only channels
  const GaussianGradsT<double> g = e.grads(25);
  auto ev = [&]() { return e.eval(); };
  fd_check("many extra", e.s.extra, all_indices(e.s.extra.size()), g.extra, ev);
  fd_check("many colors", e.s.colors, all_indices(e.s.colors.size()), g.colors, ev);
  fd_check("many mean", e.s.mean, all_indices(e.s.mean.size()), g.mean, ev);
  fd_check("many opacity_logit", e.s.opacity_logit, all_indices(e.s.opacity_logit.size()), g.opacity_logit, ev);
}

// Forward-only extra channels: backward with extra_grad_channels = G ignores the upstream gradient of channels
// [G, C) and gives the gradients of a full backward whose trailing upstream gradients are zero (to rounding:
// the channel sums are grouped differently), with exact zeros for the skipped channels.
TEST(RenderGrad, ForwardOnlyExtraChannelsAreSkipped) {
  Scene sc = random_scene(40, 40, 36, 43, 0.9, 5);
  ASSERT_EQ(sc.num_extra, 5);
  sc.add_pixel_weights(2, 43);
  EndToEnd full(sc, 6), part(sc, 6);
  const size_t P = size_t(sc.cam.width) * sc.cam.height;
  for (size_t p = 0; p < P; ++p)
    for (int c = 3; c < 5; ++c) full.we[p * 5 + c] = 0;  // part keeps non-zero values there: they must be ignored
  const GaussianGradsT<double> a = full.grads();
  const GaussianGradsT<double> b = part.grads(3);
  auto near = [](const std::vector<double>& x, const std::vector<double>& y, const char* what) {
    ASSERT_EQ(x.size(), y.size()) << what;
    for (size_t i = 0; i < x.size(); ++i) EXPECT_NEAR(x[i], y[i], 1e-12 * (1 + std::abs(x[i]))) << what << " " << i;
  };
  near(a.mean, b.mean, "mean");
  near(a.log_scale, b.log_scale, "log_scale");
  near(a.quat, b.quat, "quat");
  near(a.opacity_logit, b.opacity_logit, "opacity_logit");
  near(a.sh, b.sh, "sh");
  ASSERT_EQ(b.extra.size(), size_t(sc.n) * 5);
  for (int i = 0; i < sc.n; ++i)
    for (int c = 0; c < 5; ++c) {
      if (c < 3) EXPECT_NEAR(b.extra[i * 5 + c], a.extra[i * 5 + c], 1e-12 * (1 + std::abs(a.extra[i * 5 + c])));
      else EXPECT_EQ(b.extra[i * 5 + c], 0.0) << i << " " << c;
    }
  double any = 0;
  for (double v : a.extra) any += std::abs(v);
  EXPECT_GT(any, 0);
  EXPECT_THROW(part.grads(6), hgs::Error);
}

// dL/d(mean2d) reported by backward() is the derivative w.r.t. the projected centre with everything else
// (conic, depth, colour, opacity) fixed: check by finite differences on the renderer's own projected arrays.
TEST(RenderGrad, Mean2dIsTheProjectedCentreGradient) {
  SingleThread one_thread;
  Scene sc = random_scene(50, 40, 36, 51, 0.9, 1);
  EndToEnd e(sc, 6);
  const GaussianGradsT<double> g = e.grads();
  const ProjectedView<double> pv = e.r.projected();
  Raster2D r;
  r.s = &e.s;
  r.n = pv.n;
  r.C = e.s.num_extra;
  r.mean2d.assign(pv.mean2d, pv.mean2d + 2 * pv.n);
  r.conic.assign(pv.conic, pv.conic + 3 * pv.n);
  r.opacity.assign(pv.opacity, pv.opacity + pv.n);
  r.color.assign(pv.colors, pv.colors + 3 * pv.n);
  r.depth.assign(pv.depth, pv.depth + pv.n);
  r.radius.assign(pv.radii, pv.radii + pv.n);
  r.extra = e.s.extra;
  auto eval = [&]() {
    r.forward();
    Eval ev;
    ev.loss = dot(e.wr, r.rgb) + dot(e.wa, r.alpha) + dot(e.wd, r.dep) + dot(e.we, r.ext);
    ev.signature = r.signature();
    return ev;
  };
  const FdStats st = fd_check("mean2d", r.mean2d, all_indices(r.mean2d.size()), g.mean2d, eval);
  EXPECT_GT(st.checked, 40);
  // and it is nonzero exactly for visible Gaussians that touch a pixel
  for (int i = 0; i < pv.n; ++i)
    if (!pv.radii[i]) {
      EXPECT_EQ(g.mean2d[2 * i], 0.0);
    }
}

// ---------------------------------------------------------------------------------------------------------
template <class A, class B>
void expect_close_group(const char* name, const std::vector<A>& a, const std::vector<B>& b, double rel) {
  ASSERT_EQ(a.size(), b.size()) << name;
  double scale = 0, err = 0;
  for (size_t i = 0; i < a.size(); ++i) {
    scale = std::max(scale, std::abs(double(b[i])));
    err = std::max(err, std::abs(double(a[i]) - double(b[i])));
  }
  EXPECT_LE(err, rel * scale) << name << " (scale " << scale << ")";
}

TEST(RenderGrad, FloatPathAgreesWithDouble) {
  // The second scene has 29 extra channels (the float path moves them through 8 x 8 transposes), hard masks,
  // and is 69 pixels wide (partial batches).
  for (int sc = 0; sc < 2; ++sc) {
    Scene s = sc == 0 ? random_scene(300, 64, 48, 61, 0.9, 2) : random_scene(300, 69, 48, 62, 0.9, 29);
    if (sc == 1) s.add_label_weights(3, 6);
    RendererT<float> rf;
    RendererT<double> rd;
    RenderOutputsT<float> of;
    RenderOutputsT<double> od;
    GaussianGradsT<float> gf;
    GaussianGradsT<double> gd;
    render_with_random_grads(s, rf, of, gf, 9);
    render_with_random_grads(s, rd, od, gd, 9);
    expect_close_group("rgb", of.rgb, od.rgb, 1e-5);
    expect_close_group("extra image", of.extra, od.extra, 1e-5);
    expect_close_group("mean", gf.mean, gd.mean, 2e-4);
    expect_close_group("log_scale", gf.log_scale, gd.log_scale, 2e-4);
    expect_close_group("quat", gf.quat, gd.quat, 2e-4);
    expect_close_group("opacity_logit", gf.opacity_logit, gd.opacity_logit, 2e-4);
    expect_close_group("sh", gf.sh, gd.sh, 2e-4);
    expect_close_group("extra", gf.extra, gd.extra, 2e-4);
    expect_close_group("mean2d", gf.mean2d, gd.mean2d, 2e-4);
  }
}

TEST(RenderDeterminism, BitwiseEqualAcrossRunsAndThreadCounts) {
  Scene s = random_scene(3000, 160, 120, 71, 0.9, 3);
  const int saved = omp_get_max_threads();
  RendererT<float> r;
  RenderOutputsT<float> o1, o2, o3, o4;
  GaussianGradsT<float> g1, g2, g3, g4;
  omp_set_num_threads(2);  // 80 tiles: runs of 2 tiles per chunk (detail::tile_run)
  render_with_random_grads(s, r, o1, g1, 1);
  render_with_random_grads(s, r, o2, g2, 1);
  omp_set_num_threads(1);  // runs of 4
  render_with_random_grads(s, r, o3, g3, 1);
  omp_set_num_threads(5);  // one tile per chunk
  render_with_random_grads(s, r, o4, g4, 1);
  omp_set_num_threads(saved);
  for (const auto* o : {&o2, &o3, &o4}) {
    EXPECT_TRUE(bitwise_equal(o1.rgb, o->rgb));
    EXPECT_TRUE(bitwise_equal(o1.alpha, o->alpha));
    EXPECT_TRUE(bitwise_equal(o1.depth, o->depth));
    EXPECT_TRUE(bitwise_equal(o1.extra, o->extra));
  }
  for (const auto* g : {&g2, &g3, &g4}) {
    EXPECT_TRUE(bitwise_equal(g1.mean, g->mean));
    EXPECT_TRUE(bitwise_equal(g1.log_scale, g->log_scale));
    EXPECT_TRUE(bitwise_equal(g1.quat, g->quat));
    EXPECT_TRUE(bitwise_equal(g1.opacity_logit, g->opacity_logit));
    EXPECT_TRUE(bitwise_equal(g1.sh, g->sh));
    EXPECT_TRUE(bitwise_equal(g1.extra, g->extra));
    EXPECT_TRUE(bitwise_equal(g1.mean2d, g->mean2d));
  }
  double gsum = 0;
  for (float v : g1.mean) gsum += std::abs(v);
  EXPECT_GT(gsum, 0);
}

// The per-Gaussian and per-pair records start on a cache line (LineVector), so that each 16-float record is one
// line: with operator new's 16-byte alignment each straddled two, which cost the two-thread walks 7-10 %.
TEST(RasterWorkspace, RecordsFillWholeCacheLines) {
  static_assert(std::is_same_v<decltype(RasterWorkspace<float>::records), LineVector<float>>);
  static_assert(std::is_same_v<decltype(RasterWorkspace<float>::tile_records), LineVector<float>>);
  static_assert(std::is_same_v<decltype(RasterWorkspace<float>::chan_records), LineVector<float>>);
  static_assert(std::is_same_v<decltype(RasterWorkspace<float>::live_rows), LineVector<uint8_t>>);
  LineVector<float> v;
  LineVector<double> d;
  for (size_t n : {1, 3, 17, 1000, 123457}) {
    v.resize(n);
    d.resize(n);
    EXPECT_EQ(reinterpret_cast<uintptr_t>(v.data()) % 64, 0u) << n;
    EXPECT_EQ(reinterpret_cast<uintptr_t>(d.data()) % 64, 0u) << n;
  }
}

}  // namespace
}  // namespace hgs::render::test
