// Forward of the tiled renderer against the brute-force reference (render_ref.h): double and float pipelines,
// SH and precomputed colours, extra channels, partial tiles, culled / clamped / near-plane Gaussians.
#include <gtest/gtest.h>

#include "core/error.h"
#include "render/renderer.h"
#include "render_ref.h"

namespace hgs::render::test {
namespace {

// Pixels whose error exceeds tol. In double the pipeline makes exactly the reference's decisions, so every
// pixel must match. In float a Gaussian whose alpha at some pixel sits within float error of 1/255 (or whose
// T * (1 - alpha) sits at 1e-4) can legitimately fall on the other side of the cut-off (float conics of thin
// Gaussians carry ~1e-5 relative error): such a flip moves that pixel by up to ~alpha_threshold * T, so for
// float a handful of pixels (<= 0.5%) may differ by at most 1e-2 (times the value scale), all others must match
// to tol.
template <class T>
void expect_match(const char* what, const std::vector<T>& a, const std::vector<double>& b, double tol) {
  ASSERT_EQ(a.size(), b.size()) << what;
  size_t bad = 0;
  double worst = 0, scale = 1;
  for (double v : b) scale = std::max(scale, std::abs(v));
  for (size_t i = 0; i < a.size(); ++i) {
    const double e = std::abs(double(a[i]) - b[i]);
    bad += e > tol;
    worst = std::max(worst, e);
  }
  if (sizeof(T) == sizeof(double)) {
    EXPECT_LT(worst, tol) << what;
  } else {
    EXPECT_LE(bad * 200, a.size()) << what << ": " << bad << " of " << a.size() << " values off by > " << tol;
    EXPECT_LT(worst, 1e-2 * scale) << what;
  }
}

template <class T>
void check_against_reference(const Scene& s, double tol) {
  std::vector<std::vector<T>> store;
  const GaussianInputsT<T> g = s.inputs<T>(store);
  RendererT<T> r;
  RenderOutputsT<T> out;
  r.forward(s.cam, g, s.settings, out);
  const RefImage ref = ref_render(s, s.settings.want_depth);
  expect_match("rgb", out.rgb, ref.rgb, tol);
  expect_match("alpha", out.alpha, ref.alpha, tol);
  if (s.settings.want_depth) expect_match("depth", out.depth, ref.depth, tol * 10);  // depths are ~5
  else EXPECT_TRUE(out.depth.empty());
  expect_match("extra", out.extra, ref.extra, tol * 4);
  expect_match("weight_sums", out.weight_sums, ref.weight_sums, tol * 20);  // sums over up to ~100 pixels
  // the scene really exercises compositing: some pixels are covered, some not fully
  double amax = 0, amin = 1;
  for (double a : ref.alpha) amax = std::max(amax, a), amin = std::min(amin, a);
  EXPECT_GT(amax, 0.5);
  const auto P = ref_project(s);
  int vis = 0;
  for (int i = 0; i < s.n; ++i) {
    vis += P[i].visible;
    EXPECT_EQ(r.radii()[i], P[i].visible ? P[i].radius : 0) << "Gaussian " << i;
  }
  EXPECT_EQ(out.num_visible, vis);
}

TEST(RenderForward, MatchesBruteForceDouble) {
  for (uint32_t seed = 1; seed <= 6; ++seed) {
    Scene s = random_scene(60, 40, 36, seed, 0.95, seed % 2 ? 3 : 0);
    s.sh_degree = int(seed % 4);
    if (seed > 3) s.add_pixel_weights(2, seed);
    check_against_reference<double>(s, 1e-10);
  }
}

TEST(RenderForward, MatchesBruteForceFloat) {
  for (uint32_t seed = 11; seed <= 16; ++seed) {
    Scene s = random_scene(60, 40, 36, seed, 0.95, 2);
    if (seed % 2) s.add_pixel_weights(int(seed % 3) + 1, seed);
    check_against_reference<float>(s, 1e-5);
  }
}

TEST(RenderForward, ManyExtraChannelsAndHardMasks) {
  // 29 channels run the compositing in register chunks of 12, 12, 4 and 1; hard label masks take the path that
  // visits only the weight maps present in a batch.
  for (uint32_t seed : {41u, 42u}) {
    Scene s = random_scene(80, seed == 41 ? 40 : 45, 36, seed, 0.95, 29);  // 45: batches of 8 and of 5 pixels
    s.add_label_weights(5, seed == 41 ? 8 : 3);
    check_against_reference<double>(s, 1e-10);
    check_against_reference<float>(s, 1e-5);
  }
}

TEST(RenderForward, LargerSceneFloatWithColours) {
  Scene s = random_scene(600, 70, 50, 99, 0.95, 4);
  s.use_colors = true;
  check_against_reference<float>(s, 2e-5);
  s.use_colors = false;
  s.settings.want_depth = false;
  check_against_reference<float>(s, 2e-5);
}

TEST(RenderForward, DenseSceneHitsTransmittanceCutoff) {
  // Many opaque layers: most pixels stop on the T < 1e-4 rule, which must match the reference exactly.
  Scene s = random_scene(400, 40, 36, 5, 0.99);
  for (double& l : s.log_scale) l += 1.0;
  const RefImage ref = ref_render(s);
  int stops = 0;
  for (int c : ref.signature) stops += c == 4;
  EXPECT_GT(stops, 100);
  check_against_reference<double>(s, 1e-10);
  check_against_reference<float>(s, 1e-5);
}

TEST(RenderForward, EmptyAndCulledScenes) {
  Scene s = random_scene(10, 33, 17, 3);
  for (int i = 0; i < s.n; ++i) s.mean[3 * i + 2] = -100;  // all behind (camera looks roughly along +z)
  std::vector<std::vector<float>> store;
  GaussianInputs g = s.inputs<float>(store);
  GaussianRenderer r;
  RenderOutputs out;
  r.forward(s.cam, g, s.settings, out);
  EXPECT_EQ(out.num_visible, 0);
  for (int p = 0; p < 33 * 17; ++p) {
    EXPECT_EQ(out.alpha[p], 0.f);
    EXPECT_EQ(out.rgb[3 * p + 2], s.settings.background[2]);
  }
  g.n = 0;
  r.forward(s.cam, g, s.settings, out);
  EXPECT_EQ(out.rgb.size(), size_t(33 * 17 * 3));
}

TEST(RenderForward, BadInputIsAnError) {
  Scene s = random_scene(5, 20, 20, 3);
  std::vector<std::vector<float>> store;
  GaussianInputs g = s.inputs<float>(store);
  GaussianRenderer r;
  RenderOutputs out;
  GaussianInputs bad = g;
  bad.sh_degree = 4;
  EXPECT_THROW(r.forward(s.cam, bad, s.settings, out), hgs::Error);
  bad = g;
  bad.sh_stride = 4;
  EXPECT_THROW(r.forward(s.cam, bad, s.settings, out), hgs::Error);
  Camera c = s.cam;
  c.width = 0;
  EXPECT_THROW(r.forward(c, g, s.settings, out), hgs::Error);
  GaussianGrads gr;
  EXPECT_THROW(r.backward(OutputGrads{}, gr), hgs::Error);
}

}  // namespace
}  // namespace hgs::render::test

namespace hgs::render::test {
namespace {

// Precomputed colours win over SH; when both are passed, grads.colors carries the gradient and grads.sh stays
// empty (callers that derive colours from SH use preprocess() / preprocess_backward() instead).
TEST(RenderForward, ColoursTakePrecedenceOverSh) {
  Scene s = random_scene(30, 40, 36, 8);
  std::vector<std::vector<float>> store;
  GaussianInputs g = s.inputs<float>(store);
  std::vector<float> cols(s.colors.begin(), s.colors.end());
  GaussianRenderer r1, r2;
  RenderOutputs o1, o2;
  g.colors = cols.data();
  r1.forward(s.cam, g, s.settings, o1);
  s.use_colors = true;
  std::vector<std::vector<float>> store2;  // g's arrays must stay alive until r1.backward()
  GaussianInputs g2 = s.inputs<float>(store2);
  r2.forward(s.cam, g2, s.settings, o2);
  EXPECT_EQ(o1.rgb, o2.rgb);
  std::vector<float> w(o1.rgb.size(), 1.f);
  OutputGrads d;
  d.rgb = w.data();
  GaussianGrads gr;
  r1.backward(d, gr);
  EXPECT_TRUE(gr.sh.empty());
  ASSERT_EQ(gr.colors.size(), size_t(30 * 3));
  float sum = 0;
  for (float v : gr.colors) sum += v;
  EXPECT_GT(sum, 0.f);
}

}  // namespace
}  // namespace hgs::render::test
