// The two compilations of the rasterizer kernels (render/raster_isa.h: the portable AVX2 one and the AVX-512
// one) compute bitwise-equal results: renders and gradients of whole scenes, float and double, with extra
// channels (both channel paths), pixel-weight maps and partial batches. The finite-difference and reference tests run
// on the compilation the CPU selects, so this carries them over to the other one.
#include <gtest/gtest.h>

#include <string>

#include "core/error.h"
#include "render/raster_isa.h"
#include "render/renderer.h"
#include "render_ref.h"
#include "render_run.h"

namespace hgs::render::test {
namespace {

template <class T>
struct Result {
  RenderOutputsT<T> out;
  GaussianGradsT<T> g;
};

template <class T>
Result<T> render_with(RasterIsa isa, const Scene& s, uint32_t seed) {
  set_raster_isa(isa);
  RendererT<T> r;
  Result<T> res;
  render_with_random_grads(s, r, res.out, res.g, seed);
  return res;
}

template <class T>
void compare_isas(const Scene& s) {
  const Result<T> a = render_with<T>(RasterIsa::kAvx2, s, 5), b = render_with<T>(RasterIsa::kAvx512, s, 5);
  EXPECT_TRUE(bitwise_equal(a.out.rgb, b.out.rgb)) << "rgb";
  EXPECT_TRUE(bitwise_equal(a.out.alpha, b.out.alpha)) << "alpha";
  EXPECT_TRUE(bitwise_equal(a.out.depth, b.out.depth)) << "depth";
  EXPECT_TRUE(bitwise_equal(a.out.extra, b.out.extra)) << "extra image";
  EXPECT_TRUE(bitwise_equal(a.g.mean, b.g.mean)) << "mean";
  EXPECT_TRUE(bitwise_equal(a.g.log_scale, b.g.log_scale)) << "log_scale";
  EXPECT_TRUE(bitwise_equal(a.g.quat, b.g.quat)) << "quat";
  EXPECT_TRUE(bitwise_equal(a.g.opacity_logit, b.g.opacity_logit)) << "opacity_logit";
  EXPECT_TRUE(bitwise_equal(a.g.sh, b.g.sh)) << "sh";
  EXPECT_TRUE(bitwise_equal(a.g.extra, b.g.extra)) << "extra";
  EXPECT_TRUE(bitwise_equal(a.g.mean2d, b.g.mean2d)) << "mean2d";
  double sum = 0;
  for (T v : a.g.mean) sum += std::abs(double(v));
  EXPECT_GT(sum, 0);  // the scene has gradients to compare
}

bool have_avx512() { return raster_isa_supported(RasterIsa::kAvx512); }

TEST(RasterIsa, Avx512AndAvx2GiveBitwiseEqualFloatResults) {
  if (!have_avx512()) GTEST_SKIP() << "this CPU has no AVX-512: only the AVX2 compilation can run here";
  IsaGuard guard;
  // Plain RGB + depth; then 29 extra channels with hard label masks on a 69-pixel-wide image (partial batches).
  compare_isas<float>(random_scene(3000, 160, 120, 71, 0.9, 0));
  Scene s = random_scene(800, 69, 48, 62, 0.9, 29);
  s.add_label_weights(3, 6);
  compare_isas<float>(s);
  // 4 extra channels: composited in the walks themselves (rasterize.h's folded channel path).
  Scene f = random_scene(800, 69, 48, 63, 0.9, 4);
  f.add_label_weights(3, 6);
  compare_isas<float>(f);
}

TEST(RasterIsa, Avx512AndAvx2GiveBitwiseEqualDoubleResults) {
  if (!have_avx512()) GTEST_SKIP() << "this CPU has no AVX-512: only the AVX2 compilation can run here";
  IsaGuard guard;
  Scene s = random_scene(300, 64, 48, 61, 0.9, 5);
  s.add_label_weights(2, 6);
  compare_isas<double>(s);
  Scene f = random_scene(300, 64, 48, 64, 0.9, 3);  // the folded channel path
  f.add_label_weights(2, 6);
  compare_isas<double>(f);
}

TEST(RasterIsa, NamesAndChoice) {
  IsaGuard guard;
  EXPECT_EQ(parse_raster_isa("avx2"), RasterIsa::kAvx2);
  EXPECT_EQ(parse_raster_isa("avx512"), RasterIsa::kAvx512);
  EXPECT_STREQ(raster_isa_name(RasterIsa::kAvx512), "avx512");
  EXPECT_THROW(parse_raster_isa("sse"), Error);
  EXPECT_TRUE(raster_isa_supported(RasterIsa::kAvx2));
  set_raster_isa(RasterIsa::kAvx2);
  EXPECT_EQ(raster_isa(), RasterIsa::kAvx2);
  // HGS_RASTER_ISA: unset / empty = the best the CPU has; bad values fail naming the variable.
  EXPECT_EQ(raster_isa_from_env(nullptr), have_avx512() ? RasterIsa::kAvx512 : RasterIsa::kAvx2);
  EXPECT_EQ(raster_isa_from_env(""), raster_isa_from_env(nullptr));
  EXPECT_EQ(raster_isa_from_env("avx2"), RasterIsa::kAvx2);
  try {
    raster_isa_from_env("avx3");
    ADD_FAILURE() << "HGS_RASTER_ISA=avx3 was accepted";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("HGS_RASTER_ISA=avx3"), std::string::npos) << e.what();
  }
  if (have_avx512()) {
    EXPECT_EQ(raster_isa_from_env("avx512"), RasterIsa::kAvx512);
    set_raster_isa(RasterIsa::kAvx512);
    EXPECT_EQ(raster_isa(), RasterIsa::kAvx512);
  } else {
    EXPECT_THROW(raster_isa_from_env("avx512"), Error);
    EXPECT_THROW(set_raster_isa(RasterIsa::kAvx512), Error);
  }
}

}  // namespace
}  // namespace hgs::render::test
