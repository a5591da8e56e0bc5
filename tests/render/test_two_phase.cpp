// The two-phase renderer API (preprocess -> composite, composite_backward -> preprocess_backward):
// - it gives bitwise the one-call forward() / backward() results (float, SH and precomputed colours, extra
//   channels, pixel weights, forward-only channels), also when the phases run on a warm renderer;
// - a caller building extra channels from projected().colors between the phases (the hybrid method's q_k * c)
//   and adding their colour gradient before preprocess_backward() gets the exact gradient of the whole chain
//   (finite differences in double), bitwise the same as the precomputed-colour route (SH on every Gaussian by
//   hand, colours passed as precomputed, sh_backward by hand);
// - culled Gaussians get colour 0 without evaluating SH and no SH / mean gradient, whatever is added to their
//   colour gradient.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>

#include "core/error.h"
#include "fd_check.h"
#include "render/renderer.h"
#include "render/sh.h"
#include "render_ref.h"
#include "render_run.h"

namespace hgs::render::test {
namespace {

using namespace hgs::test;

template <class T>
std::vector<T> to(const std::vector<double>& v) {
  return std::vector<T>(v.begin(), v.end());
}

// Upstream gradients for every output of a render (float), from a seed.
struct Upstream {
  std::vector<float> rgb, alpha, depth, extra, weight_sums;
  Upstream(const RenderOutputs& out, uint32_t seed) {
    std::mt19937 rng(seed);
    rgb = to<float>(random_weights(out.rgb.size(), rng));
    alpha = to<float>(random_weights(out.alpha.size(), rng));
    depth = to<float>(random_weights(out.depth.size(), rng));
    extra = to<float>(random_weights(out.extra.size(), rng));
    weight_sums = to<float>(random_weights(out.weight_sums.size(), rng));
  }
  OutputGrads grads(int extra_grad_channels) const {
    OutputGrads d;
    d.rgb = rgb.data();
    d.alpha = alpha.data();
    d.depth = depth.empty() ? nullptr : depth.data();
    d.extra = extra.empty() ? nullptr : extra.data();
    d.weight_sums = weight_sums.empty() ? nullptr : weight_sums.data();
    d.extra_grad_channels = extra_grad_channels;
    return d;
  }
};

void expect_same_render(const RenderOutputs& a, const RenderOutputs& b) {
  EXPECT_TRUE(bitwise_equal(a.rgb, b.rgb));
  EXPECT_TRUE(bitwise_equal(a.alpha, b.alpha));
  EXPECT_TRUE(bitwise_equal(a.depth, b.depth));
  EXPECT_TRUE(bitwise_equal(a.extra, b.extra));
  EXPECT_TRUE(bitwise_equal(a.weight_sums, b.weight_sums));
  EXPECT_EQ(a.num_visible, b.num_visible);
}

void expect_same_params(const GaussianGrads& a, const GaussianGrads& b) {
  EXPECT_TRUE(bitwise_equal(a.mean, b.mean));
  EXPECT_TRUE(bitwise_equal(a.log_scale, b.log_scale));
  EXPECT_TRUE(bitwise_equal(a.quat, b.quat));
  EXPECT_TRUE(bitwise_equal(a.opacity_logit, b.opacity_logit));
  EXPECT_TRUE(bitwise_equal(a.sh, b.sh));
  EXPECT_TRUE(bitwise_equal(a.colors, b.colors));
}

// (a) One call vs two phases, float, on random scenes: SH with depth, extra channels and pixel weights; precomputed
// colours without depth and with a forward-only channel tail. Three rounds on the same renderers (warm buffers:
// backward() swaps its projected gradients into the result).
TEST(RenderTwoPhase, MatchesOneCallBitwise) {
  for (int variant = 0; variant < 2; ++variant) {
    Scene s = random_scene(500, 70, 50, 21 + variant, 0.9, 5);
    s.add_pixel_weights(2, 7);
    if (variant == 1) {
      s.use_colors = true;
      s.settings.want_depth = false;
    }
    const int grad_channels = variant == 1 ? 3 : -1;
    std::vector<std::vector<float>> store;
    const GaussianInputs g = s.inputs<float>(store);
    GaussianRenderer one, two;
    RenderOutputs o1, o2;
    GaussianGrads g1, g2;
    ProjectedGrads pg;
    for (int round = 0; round < 3; ++round) {
      one.forward(s.cam, g, s.settings, o1);
      two.preprocess(s.cam, g);
      two.composite(ChannelsT<float>{g.extra, g.num_extra}, s.settings, o2);
      expect_same_render(o1, o2);
      const Upstream up(o1, 100 + round);
      one.backward(up.grads(grad_channels), g1);
      two.composite_backward(up.grads(grad_channels), pg);
      two.preprocess_backward(pg, g2);
      expect_same_params(g1, g2);
      EXPECT_TRUE(bitwise_equal(g1.mean2d, pg.mean2d));
      EXPECT_TRUE(bitwise_equal(g1.extra, pg.extra));
      EXPECT_TRUE(g2.mean2d.empty());
      EXPECT_TRUE(g2.extra.empty());
      EXPECT_EQ(g1.sh.empty(), variant == 1);
      EXPECT_EQ(g1.colors.empty(), variant == 0);
      // the projected view is the same in both
      const ProjectedView<float> p1 = one.projected(), p2 = two.projected();
      ASSERT_EQ(p1.n, s.n);
      EXPECT_EQ(p1.num_visible, o1.num_visible);
      EXPECT_EQ(std::memcmp(p1.colors, p2.colors, sizeof(float) * 3 * s.n), 0);
      EXPECT_EQ(std::memcmp(p1.mean2d, p2.mean2d, sizeof(float) * 2 * s.n), 0);
      for (int k = 0; k < 3; ++k) EXPECT_EQ(p1.campos[k], p2.campos[k]);
    }
    double any = 0;
    for (float v : pg.extra) any += std::abs(v);
    EXPECT_GT(any, 0);
  }
}

// A caller that builds extra channels from the projected colours: extra_n = (s_n c_n, s_n) for fixed s_n
// (4 channels), and adds d c_n += s_n d extra_n[0..3) before preprocess_backward().
template <class T>
struct ColourChannels {
  std::vector<T> scale;  // [N] s_n
  std::vector<T> extra;  // [N, 4]
  void build(const ProjectedView<T>& p) {
    extra.resize(size_t(p.n) * 4);
    for (int i = 0; i < p.n; ++i) {
      for (int c = 0; c < 3; ++c) extra[4 * i + c] = scale[i] * p.colors[3 * i + c];
      extra[4 * i + 3] = scale[i];
    }
  }
  void add_colour_grad(ProjectedGradsT<T>& pg) const {
    for (size_t i = 0; i < scale.size(); ++i)
      for (int c = 0; c < 3; ++c) pg.colors[3 * i + c] += scale[i] * pg.extra[4 * i + c];
  }
  ChannelsT<T> channels() const { return ChannelsT<T>{extra.data(), 4}; }
};

// (b) Finite differences of the whole chain through the caller-built channels (double): d sh, d mean (projection
// + view direction through both the RGB and the extra channels), d log_scale, d opacity_logit.
TEST(RenderTwoPhase, ChannelsFromProjectedColoursFiniteDifferences) {
  SingleThread one_thread;
  Scene s = random_scene(50, 40, 36, 33, 0.9, 4);  // num_extra = 4 only so the reference signature sees 4 channels
  s.add_pixel_weights(2, 33);
  std::mt19937 rng(5);
  std::uniform_real_distribution<double> U(0.2, 1.5);
  ColourChannels<double> cc;
  for (int i = 0; i < s.n; ++i) cc.scale.push_back(U(rng));
  const size_t P = size_t(s.cam.width) * s.cam.height;
  const std::vector<double> wr = random_weights(3 * P, rng), wa = random_weights(P, rng), wd = random_weights(P, rng),
                            we = random_weights(4 * P, rng), ww = random_weights(size_t(s.n) * 2, rng);
  RendererT<double> r;
  RenderOutputsT<double> out;
  std::vector<std::vector<double>> store;
  auto run = [&]() {
    r.preprocess(s.cam, s.inputs<double>(store));
    cc.build(r.projected());
    r.composite(cc.channels(), s.settings, out);
    Eval e;
    e.loss = dot(wr, out.rgb) + dot(wa, out.alpha) + dot(wd, out.depth) + dot(we, out.extra) + dot(ww, out.weight_sums);
    e.signature = ref_render(s).signature;
    return e;
  };
  run();
  OutputGradsT<double> d;
  d.rgb = wr.data();
  d.alpha = wa.data();
  d.depth = wd.data();
  d.extra = we.data();
  d.weight_sums = ww.data();
  ProjectedGradsT<double> pg;
  r.composite_backward(d, pg);
  cc.add_colour_grad(pg);
  GaussianGradsT<double> g;
  r.preprocess_backward(pg, g);
  ASSERT_EQ(g.sh.size(), s.sh.size());
  EXPECT_TRUE(g.colors.empty());

  std::vector<int> idx;
  for (size_t k = 0; k < s.sh.size(); k += 5) idx.push_back(int(k));
  fd_check("two-phase sh", s.sh, idx, g.sh, run);
  fd_check("two-phase mean", s.mean, all_indices(s.mean.size()), g.mean, run);
  fd_check("two-phase log_scale", s.log_scale, all_indices(s.log_scale.size()), g.log_scale, run);
  fd_check("two-phase opacity_logit", s.opacity_logit, all_indices(s.opacity_logit.size()), g.opacity_logit, run);

  // Without the caller's colour term the sh gradient would be off: the check above can fail.
  run();
  ProjectedGradsT<double> pg2;
  r.composite_backward(d, pg2);
  GaussianGradsT<double> g2;
  r.preprocess_backward(pg2, g2);
  double diff = 0, scale = 0;
  for (size_t k = 0; k < g.sh.size(); ++k) diff += std::abs(g.sh[k] - g2.sh[k]), scale += std::abs(g.sh[k]);
  EXPECT_GT(diff, 1e-3 * scale);
}

// The precomputed-colour route (sh_forward on all N, colours passed as precomputed with the channels made from
// them, sh_backward by hand) and the two-phase route give bitwise the same float render and gradients (up to the
// sign of zero for culled Gaussians, which the precomputed-colour route runs SH on with a zero colour gradient).
TEST(RenderTwoPhase, MatchesPrecomputedColourRoute) {
  Scene s = random_scene(400, 64, 48, 44, 0.9, 4);
  std::vector<std::vector<float>> store;
  GaussianInputs g = s.inputs<float>(store);
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> U(0.2f, 1.5f);
  ColourChannels<float> now, old;
  for (int i = 0; i < s.n; ++i) now.scale.push_back(U(rng));
  old.scale = now.scale;

  GaussianRenderer r_old, r_now;
  RenderOutputs o_old, o_now;
  // precomputed-colour route
  r_old.preprocess(s.cam, g);  // only for the camera centre
  float campos[3];
  for (int k = 0; k < 3; ++k) campos[k] = r_old.projected().campos[k];
  std::vector<float> col(size_t(s.n) * 3);
  sh_forward(s.n, g.sh_degree, g.sh_stride, g.sh, g.mean, campos, (const int*)nullptr, col.data());
  GaussianInputs gc = g;
  gc.colors = col.data();
  ProjectedView<float> pc;
  pc.n = s.n;
  pc.colors = col.data();
  old.build(pc);
  gc.extra = old.extra.data();
  gc.num_extra = 4;
  r_old.forward(s.cam, gc, s.settings, o_old);
  // two-phase route
  r_now.preprocess(s.cam, g);
  now.build(r_now.projected());
  r_now.composite(now.channels(), s.settings, o_now);
  expect_same_render(o_old, o_now);

  const Upstream up(o_now, 3);
  GaussianGrads g_old, g_now;
  r_old.backward(up.grads(3), g_old);  // the fourth channel is forward-only, as the hybrid opacity channels
  for (int i = 0; i < s.n; ++i)
    for (int c = 0; c < 3; ++c) g_old.colors[3 * i + c] += old.scale[i] * g_old.extra[4 * i + c];
  g_old.sh.resize(s.sh.size());
  sh_backward(s.n, g.sh_degree, g.sh_stride, g.sh, g.mean, campos, (const int*)nullptr, g_old.colors.data(),
              g_old.sh.data(), g_old.mean.data());
  ProjectedGrads pg;
  r_now.composite_backward(up.grads(3), pg);
  now.add_colour_grad(pg);
  r_now.preprocess_backward(pg, g_now);

  auto same_values = [](const std::vector<float>& a, const std::vector<float>& b, const char* what) {
    ASSERT_EQ(a.size(), b.size()) << what;
    size_t bad = 0;
    for (size_t k = 0; k < a.size(); ++k) bad += !(a[k] == b[k]);
    EXPECT_EQ(bad, 0u) << what;
  };
  same_values(g_old.mean, g_now.mean, "mean");
  same_values(g_old.log_scale, g_now.log_scale, "log_scale");
  same_values(g_old.quat, g_now.quat, "quat");
  same_values(g_old.opacity_logit, g_now.opacity_logit, "opacity_logit");
  same_values(g_old.sh, g_now.sh, "sh");
  same_values(g_old.mean2d, pg.mean2d, "mean2d");
  same_values(g_old.extra, pg.extra, "extra");
}

// (c) Culled Gaussians: colour 0 (their SH is not evaluated: NaN coefficients stay harmless), no SH gradient and
// no mean gradient, even when the caller adds a colour gradient for them.
TEST(RenderTwoPhase, CulledGaussiansGetNoColourAndNoGradient) {
  for (int dbl = 0; dbl < 2; ++dbl) {
    Scene s = random_scene(200, 48, 40, 55, 0.9);
    // also push some far off to the side of the image (outside the frustum, in front of the camera)
    for (int i = 3; i < s.n; i += 17) {
      double* m = &s.mean[3 * i];
      const double z = s.cam.R[6] * m[0] + s.cam.R[7] * m[1] + s.cam.R[8] * m[2] + s.cam.t[2];
      for (int k = 0; k < 3; ++k) m[k] += s.cam.R[k] * 20 * (std::abs(z) + 1);  // + camera x axis
    }
    auto check = [&](auto zero) {
      using T = decltype(zero);
      // NaN SH for every Gaussian the reference culls
      const auto ref = ref_project(s);
      Scene sn = s;
      int culled = 0;
      for (int i = 0; i < s.n; ++i)
        if (!ref[i].visible) {
          ++culled;
          for (int k = 0; k < s.sh_stride * 3; ++k)
            sn.sh[size_t(i) * s.sh_stride * 3 + k] = std::numeric_limits<double>::quiet_NaN();
        }
      ASSERT_GT(culled, 12);
      std::vector<std::vector<T>> store;
      const GaussianInputsT<T> g = sn.inputs<T>(store);
      RendererT<T> r;
      r.preprocess(s.cam, g);
      const ProjectedView<T> p = r.projected();
      RenderOutputsT<T> out;
      r.composite(ChannelsT<T>{}, s.settings, out);
      std::vector<T> w(out.rgb.size(), T(1));
      OutputGradsT<T> d;
      d.rgb = w.data();
      ProjectedGradsT<T> pg;
      r.composite_backward(d, pg);
      for (T& v : pg.colors) v += T(0.5);  // a caller's colour term reaching every Gaussian
      GaussianGradsT<T> gr;
      r.preprocess_backward(pg, gr);
      int visible_with_grad = 0;
      for (int i = 0; i < s.n; ++i) {
        const T* dsh = &gr.sh[size_t(i) * s.sh_stride * 3];
        if (ref[i].visible) {
          EXPECT_GT(p.radii[i], 0) << i;
          T a = 0;
          for (int k = 0; k < s.sh_stride * 3; ++k) a += std::abs(dsh[k]);
          visible_with_grad += a > 0;
          continue;
        }
        EXPECT_EQ(p.radii[i], 0) << i;
        for (int c = 0; c < 3; ++c) EXPECT_EQ(p.colors[3 * i + c], T(0)) << i;
        for (int k = 0; k < s.sh_stride * 3; ++k) ASSERT_EQ(dsh[k], T(0)) << i << " " << k;
        for (int k = 0; k < 3; ++k) EXPECT_EQ(gr.mean[3 * i + k], T(0)) << i;
      }
      EXPECT_GT(visible_with_grad, s.n / 2);
      for (T v : out.rgb) ASSERT_FALSE(std::isnan(v));
    };
    if (dbl) check(double(0));
    else check(float(0));
  }
}

TEST(RenderTwoPhase, OutOfOrderCallsAreErrors) {
  Scene s = random_scene(20, 32, 32, 3, 0.9, 2);
  std::vector<std::vector<float>> store;
  const GaussianInputs g = s.inputs<float>(store);
  GaussianRenderer r;
  RenderOutputs out;
  ProjectedGrads pg;
  GaussianGrads gr;
  EXPECT_THROW(r.composite(Channels{}, s.settings, out), hgs::Error);
  EXPECT_THROW(r.preprocess_backward(pg, gr), hgs::Error);
  r.preprocess(s.cam, g);
  EXPECT_THROW(r.composite_backward(OutputGrads{}, pg), hgs::Error);
  EXPECT_THROW(r.preprocess_backward(pg, gr), hgs::Error);  // gradients not sized for N
  EXPECT_THROW(r.composite(Channels{nullptr, 2}, s.settings, out), hgs::Error);
  r.composite(Channels{g.extra, 2}, s.settings, out);
  r.composite_backward(OutputGrads{}, pg);
  r.preprocess_backward(pg, gr);
  r.preprocess(s.cam, g);  // a new preprocess needs a new composite before composite_backward
  EXPECT_THROW(r.composite_backward(OutputGrads{}, pg), hgs::Error);
}

}  // namespace
}  // namespace hgs::render::test
