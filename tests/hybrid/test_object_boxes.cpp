// The object losses' boxes (hybrid/object_boxes.cpp): with dilation 0, each object's scored box R_k is the hull
// of the pixels where its colour or opacity differs bitwise from the base render's or its label is k, computed
// here pixel by pixel. Checked on the renders as training hands them over (the base render plus a difference plane
// per object, written only in flagged tiles, the others +0 whatever their memory holds: NaN here), on the same
// planes without flags, and on the objects' complete values interleaved per pixel; with -0 in the base (an
// unwritten +0 then differs from it), differences too small to change the base's bits, an object with the same
// label as another, labels of no object, an object label no pixel can carry, and objects absent from whole rows
// or the whole image; at 1 and 3 threads, and again after release().
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include "core/image.h"
#include "hybrid/object_channels.h"
#include "hybrid/object_losses.h"

using namespace hgs;
using namespace hgs::hybrid;

namespace {

uint32_t bits(float v) { return std::bit_cast<uint32_t>(v); }

std::string str(const PixelBox& b) {
  char s[96];
  std::snprintf(s, sizeof s, "[%d, %d) x [%d, %d)", b.x0, b.x1, b.y0, b.y1);
  return s;
}

}  // namespace

TEST(ObjectBoxes, BoxesAreTheHullOfTheDifferingAndLabelledPixels) {
  constexpr int W = 53, H = 37, kTile = 6;  // tiles cut at the right and bottom edges
  // Objects 1 and 2 share label 4; label 70000 fits no pixel; object 5's label sits in one corner pixel only.
  const std::vector<int> objs = {1, 4, 4, 9, 70000, 2};
  const int J = static_cast<int>(objs.size());
  const long HW = long(W) * H;
  std::mt19937 rng(61);
  std::uniform_real_distribution<float> U(0.05f, 1.f);
  Image image(W, H, 3);
  for (float& v : image.px) v = U(rng);
  LabelMap lab(W, H, 0);
  auto fill = [&](int x0, int y0, int x1, int y1, uint16_t l) {
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) lab.at(x, y) = l;
  };
  fill(3, 4, 11, 9, 1);
  fill(30, 2, 34, 20, 4);
  fill(40, 25, 50, 30, 7);  // a label of no object
  lab.at(17, 33) = 9, lab.at(45, 1) = 9;
  lab.at(W - 1, H - 1) = 2;
  // The base render [H, W, 4]: colour and opacity (a -0 is set below).
  std::vector<float> base0(size_t(HW) * 4);
  for (float& v : base0) v = U(rng);
  // Each object's difference from the base [J, H, W, 4]: +0, except in rectangles (value v: a real difference,
  // or 1e-12 added to a base value near 0.5, which leaves its bits).
  std::vector<float> planes(size_t(J) * HW * 4, 0.f);
  auto delta = [&](int j, int x0, int y0, int x1, int y1, bool absorbed) {
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x)
        for (int c = 0; c < 4; ++c) planes[(size_t(j) * HW + size_t(y) * W + x) * 4 + c] = absorbed ? 1e-12f : U(rng);
  };
  delta(0, 5, 5, 14, 12, false);
  delta(0, 16, 5, 22, 8, true);  // written but the same bits: not in the box
  delta(1, 25, 10, 38, 15, false);
  delta(2, 0, 22, 2, 30, false);    // the left border, rows 22-29
  delta(2, 50, 25, 53, 26, false);  // and the right border in row 25
  delta(3, 10, 30, 12, 37, true);   // only absorbed differences: the box is its label's pixels
  // object 4: nothing; object 5: a difference at the top-right corner besides its label at the bottom-right
  delta(5, 52, 0, 53, 1, false);
  // Flags as the renderer's group_live_tiles: every tile with a set bit, and every 4th other tile; memory of the
  // others NaN.
  const int tx = (W + kTile - 1) / kTile, tiles = tx * ((H + kTile - 1) / kTile);
  std::vector<uint8_t> live(size_t(J) * tiles, 0);
  auto tile_of = [&](long p) { return (p / W / kTile) * tx + p % W / kTile; };
  for (int j = 0; j < J; ++j)
    for (long p = 0; p < HW; ++p)
      for (int c = 0; c < 4; ++c) live[size_t(j) * tiles + tile_of(p)] |= bits(planes[(j * HW + p) * 4 + c]) != 0;
  int other = 0;
  for (uint8_t& f : live)
    if (!f && ++other % 4 == 0) f = 1;
  live[size_t(2) * tiles + tile_of(20 * W + 20)] = 1;  // (20, 20): written (+0) by object 2, not by object 4
  live[size_t(4) * tiles + tile_of(20 * W + 20)] = 0;
  std::vector<float> unwritten = planes;
  for (int j = 0; j < J; ++j)
    for (long p = 0; p < HW; ++p)
      if (!live[size_t(j) * tiles + tile_of(p)]) std::fill_n(&unwritten[(j * HW + p) * 4], 4, std::nanf(""));
  // Twice: the base as drawn, then with -0 in one colour channel at (20, 20): every object's value there, base +
  // difference or an unwritten +0, is +0 (-0 + +0 = +0), so it differs from the base in every object's render.
  for (bool negative_zero : {false, true}) {
    std::vector<float> base = base0;
    if (negative_zero) base[(size_t(20) * W + 20) * 4 + 1] = -0.f;
    // The complete values interleaved per pixel (ObjectLayout with the base), for the path that copies them out.
    const ObjectLayout lay{J, 0, true};
    std::vector<float> extra(size_t(HW) * lay.total());
    for (long p = 0; p < HW; ++p) {
      float* e = &extra[size_t(p) * lay.total()];
      const float* b = &base[size_t(p) * 4];
      for (int c = 0; c < 3; ++c) e[lay.base_color() + c] = b[c];
      e[lay.base_opacity()] = b[3];
      for (int j = 0; j < J; ++j) {
        const float* d = &planes[(j * HW + p) * 4];
        for (int c = 0; c < 3; ++c) e[lay.color(j) + c] = b[c] + d[c];
        e[lay.opacity(j)] = b[3] + d[3];
      }
    }
    // Expected, pixel by pixel: object j's value base + difference (+0 where unwritten) against the base's bits, and
    // its label.
    std::vector<PixelBox> want(J);
    for (int j = 0; j < J; ++j) {
      PixelBox b{W, H, 0, 0};
      for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
          const long p = long(y) * W + x;
          bool hit = lab.v[p] == objs[j];
          for (int c = 0; c < 4; ++c) {
            const float d = live[size_t(j) * tiles + tile_of(p)] ? planes[(j * HW + p) * 4 + c] : 0.f;
            hit |= bits(base[size_t(p) * 4 + c] + d) != bits(base[size_t(p) * 4 + c]);
          }
          if (hit) b = {std::min(b.x0, x), std::min(b.y0, y), std::max(b.x1, x + 1), std::max(b.y1, y + 1)};
        }
      want[j] = b.empty() ? PixelBox{} : b;
    }
    // The cases the fixture must hold.
    if (!negative_zero) {
      EXPECT_EQ(str(want[0]), str(PixelBox{3, 4, 14, 12}));   // label and difference; the absorbed ones not
      EXPECT_EQ(str(want[1]), str(PixelBox{25, 2, 38, 20}));  // label 4 and its difference
      EXPECT_EQ(str(want[2]), str(PixelBox{0, 2, W, 30}));    // label 4 (rows 2-19), differences at both borders
      EXPECT_EQ(str(want[3]), str(PixelBox{17, 1, 46, 34}));  // its two label pixels (differences absorbed)
      EXPECT_TRUE(want[4].empty());
      EXPECT_EQ(str(want[5]), str(PixelBox{52, 0, 53, 37}));  // a corner difference and the opposite corner's label
    } else {
      EXPECT_EQ(str(want[1]), str(PixelBox{20, 2, 38, 21}));
      EXPECT_EQ(str(want[4]), str(PixelBox{20, 20, 21, 21}));
    }
    const ObjectRenders flagged =
        ObjectRenders::sparse(base.data(), 4, 3, unwritten.data(), J, HW).with_live_tiles(live.data(), kTile, W, H);
    const ObjectRenders planar = ObjectRenders::sparse(base.data(), 4, 3, planes.data(), J, HW);
    const ObjectRenders inter = ObjectRenders::interleaved(extra.data(), lay);
    const int threads = omp_get_max_threads();
    for (int t : {1, 3}) {
      omp_set_num_threads(t);
      for (const auto& [name, r] :
           {std::pair{"flagged planes", &flagged}, std::pair{"planes", &planar}, std::pair{"interleaved", &inter}}) {
        ObjectLosses losses(HybridConfig{}, {.max_box_fraction = 2.0, .dilation = 0});
        losses(image, lab, *r, objs, {});
        const std::vector<PixelBox>& got = losses.gradients().box;
        ASSERT_EQ(int(got.size()), J);
        for (int j = 0; j < J; ++j)
          EXPECT_EQ(str(got[j]), str(want[j])) << name << ", object " << j << ", " << t << " threads";
        losses.release();  // its buffers freed, the label lookup too: the next call builds them again
        losses(image, lab, *r, objs, {});
        for (int j = 0; j < J; ++j)
          EXPECT_EQ(str(losses.gradients().box[j]), str(want[j])) << name << ", after release(), object " << j;
      }
    }
    omp_set_num_threads(threads);
  }
}
