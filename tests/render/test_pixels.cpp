// The forward at chosen pixels (RendererT::depth_at, rasterize_pixels.cpp) against the whole-image forward: at every
// chosen pixel its alpha and depth are composite()'s bits, for any choice (every pixel, a few, one, one tile,
// none), float and double, on both compilations of the kernels; tile_pixels() against a brute-force grouping.
#include <gtest/gtest.h>

#include <cstring>
#include <random>
#include <vector>

#include "core/error.h"
#include "render/raster_isa.h"
#include "render/rasterize.h"
#include "render/renderer.h"
#include "render_ref.h"
#include "render_run.h"

namespace hgs::render::test {
namespace {

template <class T>
bool same_bits(T a, T b) {
  return std::memcmp(&a, &b, sizeof(T)) == 0;
}

// Chosen pixels of a W x H image: every pixel with probability `density` (1: all, 0: none).
std::vector<uint8_t> random_choice(int W, int H, double density, uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  std::vector<uint8_t> c(size_t(W) * H);
  for (auto& v : c) v = U(rng) < density;
  return c;
}

// depth_at of `chosen` against composite() of the same preprocess, bitwise; returns the chosen pixels whose
// transmittance ended below 1e-3 (so that the cut-off is known to have been exercised).
template <class T>
int check_choice(const Scene& s, const std::vector<uint8_t>& chosen) {
  std::vector<std::vector<T>> store;
  RendererT<T> r;
  r.preprocess(s.cam, s.inputs<T>(store));
  RenderOutputsT<T> out;
  r.composite(ChannelsT<T>{}, s.settings, out);
  TilePixels px;
  tile_pixels(s.cam.width, s.cam.height, chosen.data(), px);
  std::vector<T> alpha(px.pixel.size(), T(-7)), depth(px.pixel.size(), T(-7));
  r.depth_at(px, alpha.data(), depth.data());
  int deep = 0, wrong = 0;
  for (size_t i = 0; i < px.pixel.size(); ++i) {
    const int p = px.pixel[i];
    if (!same_bits(alpha[i], out.alpha[p]) || !same_bits(depth[i], out.depth[p])) {
      if (++wrong <= 3)
        ADD_FAILURE() << "pixel " << p << ": alpha " << alpha[i] << " vs " << out.alpha[p] << ", depth " << depth[i]
                      << " vs " << out.depth[p];
    }
    deep += out.alpha[p] > T(1 - 1e-3);
  }
  EXPECT_EQ(wrong, 0);
  return deep;
}

template <class T>
void check_scene(const Scene& s, uint32_t seed) {
  const int W = s.cam.width, H = s.cam.height;
  int deep = 0;
  for (double density : {1.0, 0.3, 0.03, 0.0}) deep += check_choice<T>(s, random_choice(W, H, density, seed));
  std::vector<uint8_t> one(size_t(W) * H, 0);
  one[size_t(H / 2) * W + W / 3] = 1;  // a single pixel
  check_choice<T>(s, one);
  std::vector<uint8_t> tile(size_t(W) * H, 0);  // the whole second tile of the second tile row
  for (int y = 16; y < std::min(H, 32); ++y)
    for (int x = 16; x < std::min(W, 32); ++x) tile[size_t(y) * W + x] = 1;
  check_choice<T>(s, tile);
  EXPECT_GT(deep, 0) << "no chosen pixel reached the transmittance cut-off region";
}

TEST(DepthAt, FloatIsCompositeBitwiseAtEveryChoice) {
  on_each_isa([] {
    check_scene<float>(random_scene(3000, 160, 120, 71, 0.99), 1);
    check_scene<float>(random_scene(800, 69, 48, 62, 0.9), 2);  // partial tiles and batches at the borders
  });
}

TEST(DepthAt, DoubleIsCompositeBitwiseAtEveryChoice) {
  on_each_isa([] { check_scene<double>(random_scene(1500, 69, 48, 64, 0.99), 3); });
}

TEST(DepthAt, FailsWithoutPreprocessOrWithAnotherImagesPixels) {
  const Scene s = random_scene(200, 64, 48, 65);
  std::vector<std::vector<float>> store;
  GaussianRenderer r;
  TilePixels px;
  const std::vector<uint8_t> all(size_t(64) * 48, 1);
  tile_pixels(64, 48, all.data(), px);
  std::vector<float> a(px.pixel.size()), d(px.pixel.size());
  EXPECT_THROW(r.depth_at(px, a.data(), d.data()), hgs::Error);
  r.preprocess(s.cam, s.inputs<float>(store));
  TilePixels other;
  const std::vector<uint8_t> big(size_t(80) * 48, 1);
  tile_pixels(80, 48, big.data(), other);
  EXPECT_THROW(r.depth_at(other, a.data(), d.data()), hgs::Error);
  RenderOutputs out;
  r.composite(Channels{}, s.settings, out);
  r.depth_at(px, a.data(), d.data());
  ProjectedGrads pg;
  EXPECT_THROW(r.composite_backward(OutputGrads{}, pg), hgs::Error);  // depth_at rebuilt what backward reads
}

TEST(TilePixels, GroupsEachChosenPixelOnceByTileAndQuadrant) {
  for (auto [W, H] : {std::pair{69, 48}, std::pair{1, 1}, std::pair{17, 33}, std::pair{16, 16}}) {
    SCOPED_TRACE(testing::Message() << W << "x" << H);
    const std::vector<uint8_t> chosen = random_choice(W, H, 0.4, uint32_t(W * 100 + H));
    TilePixels px;
    tile_pixels(W, H, chosen.data(), px);
    const int tx = (W + 15) / 16, ty = (H + 15) / 16;
    ASSERT_EQ(px.start.size(), size_t(tx * ty + 1));
    std::vector<int> want;  // brute force: tile by tile, quadrant by quadrant, row by row
    for (int t = 0; t < tx * ty; ++t) {
      EXPECT_EQ(px.start[t], int(want.size()));
      for (int q = 0; q < 4; ++q)
        for (int y = (t / tx) * 16 + (q / 2) * 8; y < std::min(H, (t / tx) * 16 + (q / 2) * 8 + 8); ++y)
          for (int x = (t % tx) * 16 + (q % 2) * 8; x < std::min(W, (t % tx) * 16 + (q % 2) * 8 + 8); ++x)
            if (chosen[size_t(y) * W + x]) want.push_back(y * W + x);
    }
    EXPECT_EQ(px.start.back(), int(want.size()));
    EXPECT_EQ(px.pixel, want);
  }
}

}  // namespace
}  // namespace hgs::render::test
