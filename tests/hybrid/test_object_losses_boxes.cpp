// ObjectLosses with boxes (object_losses.h): scoring each object inside the box where it differs from the base
// render, plus the base pair once per view, gives the values and the full colour gradient of scoring every
// object over the whole image (ObjectLossOptions::boxes = false), up to float rounding. Checked on synthetic
// renders (base + a delta in a few regions: objects inside the image, touching its border, covering all of it,
// absent from the render with or without mask pixels) and on a real composite of object_channels() by the
// renderer, for BRO on / off, scale-invariant or not, with and without the scale rule, three lambda_dssim and
// three band kernels; the sparse gradient description against the dense one; and a dilation one pixel short of
// the dependency radius is caught. Also the two helpers the box path adds, train::ssim_map and bro_parts (on
// thin images too), ssim_map_rows' passes on the target's support alone against the full ones (bitwise), the
// sparse path's layouts against the interleaved one (bitwise), and a count mismatch between the renders and the
// objects refused.
#include <gtest/gtest.h>
#include <omp.h>

#include <algorithm>
#include <bit>
#include <cmath>
#include <random>
#include <string>
#include <vector>

#include "core/error.h"
#include "hybrid/bro.h"
#include "hybrid/object_channels.h"
#include "hybrid/object_losses.h"
#include "render/renderer.h"
#include "train/ssim.h"

using namespace hgs;
using namespace hgs::hybrid;

namespace {

// One view's inputs to ObjectLosses.
struct Case {
  int W = 0, H = 0;
  ObjectLayout lay;
  std::vector<int> objs;     // [J]
  Image image;               // [H, W, 3]
  LabelMap lab;              // [H, W]
  std::vector<float> extra;  // [H, W, lay.total()]
};

struct Result {
  ObjectLossValues v;
  std::vector<float> d;  // [H, W, C]
  std::vector<PixelBox> boxes;
};

Result run(const Case& c, const HybridConfig& cfg, const ObjectLossOptions& opt) {
  ObjectLosses losses(cfg, opt);
  Result r;
  r.d.assign(c.extra.size(), 0.f);
  r.v = losses(c.image, c.lab, c.extra.data(), c.lay, c.objs, r.d.data());
  r.boxes = losses.gradients().box;
  return r;
}

// Largest |a - b| over the gradient, and the largest |ref|.
void grad_error(const Result& ref, const Result& got, double& err, double& scale) {
  err = scale = 0;
  for (size_t i = 0; i < ref.d.size(); ++i) {
    err = std::max(err, double(std::abs(ref.d[i] - got.d[i])));
    scale = std::max(scale, double(std::abs(ref.d[i])));
  }
}

void expect_same(const Result& ref, const Result& got, const std::string& what) {
  EXPECT_NEAR(got.v.app, ref.v.app, 1e-5 * std::abs(ref.v.app) + 1e-12) << what;
  EXPECT_NEAR(got.v.bro, ref.v.bro, 1e-5 * std::abs(ref.v.bro) + 1e-12) << what;
  double err, scale;
  grad_error(ref, got, err, scale);
  ASSERT_GT(scale, 0) << what;
  EXPECT_LE(err, 1e-5 * scale) << what;
}

// A smooth random field in [0, 1]: a few Gaussian bumps. [H, W]
std::vector<float> bumps(int W, int H, int count, std::mt19937& rng) {
  std::uniform_real_distribution<float> U(0, 1);
  std::vector<float> f(size_t(W) * H, 0.f);
  for (int b = 0; b < count; ++b) {
    const float cx = U(rng) * W, cy = U(rng) * H, s = 3 + 8 * U(rng), a = U(rng);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x)
        f[size_t(y) * W + x] += a * std::exp(-((x - cx) * (x - cx) + (y - cy) * (y - cy)) / (2 * s * s));
  }
  for (auto& v : f) v = std::min(v, 1.f);
  return f;
}

// A rectangle [x0, x1) x [y0, y1) with a disc cut into it (a blob with straight and round edges).
struct Region {
  int x0, y0, x1, y1;
  bool inside(int x, int y) const {
    if (x < x0 || x >= x1 || y < y0 || y >= y1) return false;
    const float cx = 0.5f * (x0 + x1), cy = 0.5f * (y0 + y1), r = 0.3f * std::min(x1 - x0, y1 - y0);
    return (x - cx) * (x - cx) + (y - cy) * (y - cy) > r * r || (x + y) % 3 == 0;
  }
};

// Synthetic view, 80 x 60, objects {0, 2, 3, 5, 6, 7} and one further channel with gradient:
//   0  background: label everywhere else, render deltas in regions at opposite corners (box = the image);
//   2  label rectangle and a render delta beside it, inside the image;
//   3  label and delta touching the top-left corner;
//   5  absent: neither label pixels nor a delta (its channels equal the base);
//   6  label pixels but no delta (absent from the render);
//   7  a delta touching the right border, no label pixels.
Case synthetic(unsigned seed) {
  Case c;
  c.W = 80;
  c.H = 60;
  c.objs = {0, 2, 3, 5, 6, 7};
  const int J = 6, W = c.W, H = c.H;
  c.lay = ObjectLayout{J, 1, true};
  const int C = c.lay.total();
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(0, 1);
  c.image = Image(W, H, 3);
  for (auto& v : c.image.px) v = U(rng);
  const Region labels[J] = {{0, 0, 0, 0}, {12, 10, 28, 24}, {0, 0, 14, 11},
                            {0, 0, 0, 0}, {50, 38, 62, 50}, {0, 0, 0, 0}};
  c.lab = LabelMap(W, H, 0);
  for (int j = 1; j < J; ++j)
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x)
        if (labels[j].inside(x, y)) c.lab.at(x, y) = uint16_t(c.objs[j]);
  const std::vector<std::vector<Region>> deltas = {{{0, 0, 9, 7}, {70, 52, 80, 60}, {30, 25, 45, 40}},
                                                   {{20, 14, 36, 30}},
                                                   {{0, 0, 10, 6}},
                                                   {},
                                                   {},
                                                   {{72, 20, 80, 33}}};
  const std::vector<float> br = bumps(W, H, 6, rng), bg = bumps(W, H, 6, rng), bb = bumps(W, H, 6, rng),
                           bo = bumps(W, H, 5, rng);
  c.extra.assign(size_t(W) * H * C, 0.f);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const size_t p = size_t(y) * W + x;
      float* e = &c.extra[p * C];
      const float base[4] = {0.5f * br[p], 0.5f * bg[p], 0.5f * bb[p], bo[p] > 0.3f ? 0.5f * bo[p] : 0.f};
      for (int i = 0; i < 4; ++i) e[c.lay.base_color() + i] = base[i];
      e[c.lay.other()] = U(rng);
      for (int j = 0; j < J; ++j) {
        bool in = false;
        for (const Region& r : deltas[j]) in |= r.inside(x, y);
        const float dq = in ? 0.5f * U(rng) : 0.f;  // q_k - b_n >= 0: the object is the base plus something
        for (int i = 0; i < 3; ++i) e[c.lay.color(j) + i] = in ? base[i] + dq * (0.3f + U(rng)) : base[i];
        e[c.lay.opacity(j)] = in ? base[3] + dq : base[3];
      }
    }
  return c;
}

// The configurations compared: BRO on / off, scale-invariant or not, scale rule on / off, lambda_dssim and the
// band kernel varied.
std::vector<std::pair<std::string, HybridConfig>> configs() {
  std::vector<std::pair<std::string, HybridConfig>> out;
  HybridConfig d;
  out.push_back({"default", d});
  HybridConfig c = d;
  c.bro_scale_invariant = false;
  out.push_back({"bro_plain_gradient", c});
  c = d;
  c.use_bro = false;
  out.push_back({"no_bro", c});
  c = d;
  c.lambda_bro = 0;
  c.lambda_dssim = 0;
  out.push_back({"no_bro_l1_only", c});
  c = d;
  c.lambda_dssim = 1;
  c.bro_image_norm = false;
  out.push_back({"ssim_only_no_scale_rule", c});
  c = d;
  c.bro_kernel = 3;
  c.lambda_app = 0.5f;
  c.lambda_bro = 2;
  out.push_back({"kernel3", c});
  c = d;
  c.bro_kernel = 21;  // a band radius above the SSIM gradient's: the dependency radius is 11
  c.bro_scale_invariant = false;
  out.push_back({"kernel21_plain", c});
  return out;
}

PixelBox whole(const Case& c) { return {0, 0, c.W, c.H}; }

}  // namespace

TEST(ObjectLossesBoxes, SyntheticMatchesTheWholeImageScoring) {
  const Case c = synthetic(7);
  for (const auto& [name, cfg] : configs()) {
    const Result ref = run(c, cfg, {.boxes = false});
    ASSERT_GT(ref.v.app, 0) << name;
    if (cfg.use_bro && cfg.lambda_bro > 0) {
      ASSERT_GT(ref.v.bro, 0) << name;
    }
    const Result def = run(c, cfg, {});
    expect_same(ref, def, name + " default boxes");
    // Every object on its box, the background's crop being the whole image.
    const Result all = run(c, cfg, {.max_box_fraction = 1.0});
    expect_same(ref, all, name + " all boxes");
    // The boxes as described: the background over the image, 5 absent, the others strictly smaller.
    ASSERT_EQ(def.boxes.size(), 6u);
    EXPECT_EQ(def.boxes[0].area(), whole(c).area()) << name;
    EXPECT_TRUE(def.boxes[3].empty()) << name;
    for (int j : {1, 2, 4, 5}) {
      EXPECT_FALSE(def.boxes[j].empty()) << name << " object " << j;
      EXPECT_LT(def.boxes[j].area(), whole(c).area() / 2) << name << " object " << j;
    }
    EXPECT_EQ(def.boxes[2].x0, 0) << name;  // object 3 touches the top-left corner
    EXPECT_EQ(def.boxes[2].y0, 0) << name;
    EXPECT_EQ(def.boxes[5].x1, c.W) << name;  // object 7 the right border
  }
}

TEST(ObjectLossesBoxes, WithoutTheBaseRenderTheOptionChangesNothing) {
  Case c = synthetic(8);
  // The same channels without the 4 base channels: boxes need them, so both run the whole-image path.
  ObjectLayout lay{c.lay.J, c.lay.S, false};
  std::vector<float> ex(size_t(c.W) * c.H * lay.total());
  for (size_t p = 0; p < size_t(c.W) * c.H; ++p)
    std::copy_n(&c.extra[p * c.lay.total()], lay.total(), &ex[p * lay.total()]);
  const Result with_base = run(c, HybridConfig{}, {.boxes = false});
  c.extra = ex;
  c.lay = lay;
  const Result a = run(c, HybridConfig{}, {}), b = run(c, HybridConfig{}, {.boxes = false});
  EXPECT_EQ(a.v.app, b.v.app);
  EXPECT_EQ(a.v.bro, b.v.bro);
  EXPECT_EQ(a.v.app, with_base.v.app);  // the base channels themselves change nothing
  for (size_t p = 0; p < size_t(c.W) * c.H; ++p)
    for (int i = 0; i < lay.total(); ++i) ASSERT_EQ(a.d[p * lay.total() + i], b.d[p * lay.total() + i]);
}

TEST(ObjectLossesBoxes, SparseRendersAndCompactGradientsAreTheInterleavedOnesBitwise) {
  // The sparse path's layout (ObjectRenders::sparse: the base render's dense channels, here with 2 other channels
  // between its colour and opacity, and each object's difference from them in [H, W, 4 J] groups; gradients to
  // [H, W, 3 J] and their sum at a stride of 5) gives the values and every gradient bit of the interleaved layout
  // holding base + difference, with boxes and over whole images, BRO on and off; likewise the gradients on demand.
  Case c = synthetic(11);
  const int C = c.lay.total(), J = c.lay.J, CD = 6;
  const long HW = long(c.W) * c.H;
  std::vector<float> dense(size_t(HW) * CD, std::nanf("")), groups(size_t(HW) * 4 * J);
  for (long p = 0; p < HW; ++p) {
    float* e = &c.extra[size_t(p) * C];
    float* d = &dense[size_t(p) * CD];
    for (int k = 0; k < 3; ++k) d[k] = e[c.lay.base_color() + k];
    d[5] = e[c.lay.base_opacity()];
    for (int j = 0; j < J; ++j)
      for (int k = 0; k < 4; ++k) {
        float& v = e[k < 3 ? c.lay.color(j) + k : c.lay.opacity(j)];
        float& g = groups[(size_t(p) * J + j) * 4 + k];
        g = v - d[k < 3 ? k : 5];
        v = d[k < 3 ? k : 5] + g;  // the interleaved channel: base + difference, as the dense renderer's sum
      }
  }
  const ObjectRenders sparse = ObjectRenders::sparse(dense.data(), CD, 5, groups.data(), J);
  ASSERT_EQ(sparse.J(), J);
  for (bool bro : {true, false})
    for (bool boxes : {true, false}) {
      HybridConfig cfg;
      cfg.use_bro = bro;
      ObjectLosses a(cfg, {.boxes = boxes}), b(cfg, {.boxes = boxes});
      std::vector<float> d(c.extra.size(), 0.f), sum(size_t(HW) * 3);
      const ObjectLossValues va = a(c.image, c.lab, c.extra.data(), c.lay, c.objs, d.data(), sum.data());
      std::vector<float> g(size_t(HW) * 3 * J, std::nanf("")), sum5(size_t(HW) * 5, std::nanf(""));
      const ObjectLossValues vb = b(c.image, c.lab, sparse, c.objs, {g.data(), 3L * J, sum5.data() + 1, 5});
      const std::string tag = std::string(bro ? "BRO" : "no BRO") + (boxes ? ", boxes" : ", whole images");
      EXPECT_EQ(va.app, vb.app) << tag;
      EXPECT_EQ(va.bro, vb.bro) << tag;
      double scale = 0;
      for (long p = 0; p < HW; ++p)
        for (int k = 0; k < 3; ++k) {
          for (int j = 0; j < J; ++j) {
            const float x = d[size_t(p) * C + c.lay.color(j) + k], y = g[size_t(p) * 3 * J + 3 * j + k];
            ASSERT_EQ(std::bit_cast<uint32_t>(x), std::bit_cast<uint32_t>(y)) << tag << ", pixel " << p;
            scale = std::max(scale, double(std::abs(x)));
          }
          ASSERT_EQ(std::bit_cast<uint32_t>(sum[size_t(p) * 3 + k]),
                    std::bit_cast<uint32_t>(sum5[size_t(p) * 5 + 1 + k]))
              << tag << ", pixel " << p;
        }
      EXPECT_GT(scale, 0) << tag;
      for (long p = 0; p < HW; ++p) {  // the sum's neighbours untouched
        ASSERT_TRUE(std::isnan(sum5[size_t(p) * 5])) << tag;
        ASSERT_TRUE(std::isnan(sum5[size_t(p) * 5 + 4])) << tag;
      }
      // The gradients on demand (gradient_row, what the renderer reads without the [H, W, 3 J] buffer): the same
      // bits, in rows cut at every offset and length; and the sum alone (colour null) the same sum.
      std::vector<float> row(size_t(c.W) * 3);
      for (int j = 0; j < J; ++j)
        for (int y = 0; y < c.H; ++y)
          for (int x0 = 0; x0 < c.W; x0 += 7) {
            const int n = std::min(1 + (x0 + y) % 9, c.W - x0);
            std::fill(row.begin(), row.end(), std::nanf(""));
            b.gradient_row(j, y, x0, n, row.data());
            for (int l = 0; l < n * 3; ++l)
              ASSERT_EQ(std::bit_cast<uint32_t>(row[l]),
                        std::bit_cast<uint32_t>(
                            g[(size_t(y) * c.W + x0) * 3 * J + size_t(l / 3) * 3 * J + 3 * j + l % 3]))
                  << tag << ", object " << j << " at " << x0 + l / 3 << "," << y;
            ASSERT_TRUE(std::isnan(row[n * 3])) << tag;  // nothing past the n pixels
          }
      std::vector<float> sum_only(size_t(HW) * 3, std::nanf(""));
      b(c.image, c.lab, sparse, c.objs, {nullptr, 0, sum_only.data(), 3});
      for (long p = 0; p < HW; ++p)
        for (int k = 0; k < 3; ++k)
          ASSERT_EQ(std::bit_cast<uint32_t>(sum_only[size_t(p) * 3 + k]),
                    std::bit_cast<uint32_t>(sum5[size_t(p) * 5 + 1 + k]))
              << tag << ", pixel " << p;
      // ... and it is the sum of the values on demand, in object order.
      for (int y = 0; y < c.H; ++y) {
        std::vector<float> s(size_t(c.W) * 3, 0.f);
        for (int j = 0; j < J; ++j) {
          b.gradient_row(j, y, 0, c.W, row.data());
          for (int i = 0; i < c.W * 3; ++i) s[i] += row[i];
        }
        for (int i = 0; i < c.W * 3; ++i)
          ASSERT_EQ(std::bit_cast<uint32_t>(s[i]), std::bit_cast<uint32_t>(sum_only[size_t(y) * c.W * 3 + i]))
              << tag << ", row " << y;
      }
    }
}

TEST(ObjectLossesBoxes, ObjectPlanesAreTheInterleavedGroupsBitwise) {
  // The groups as one plane per object ([J, H, W, 4], the renderer's ChannelsT::group_planes, which the crops read
  // in place instead of copying the objects out) give the values, the gradients and the sum of the interleaved
  // groups bit for bit, with boxes and over whole images, BRO on and off, and a background scored whole; and so
  // do planes written only in flagged tiles (ObjectRenders::live, the renderer's group_live_tiles).
  Case c = synthetic(13);
  const int C = c.lay.total(), J = c.lay.J, CD = 6;
  const long HW = long(c.W) * c.H;
  std::vector<float> dense(size_t(HW) * CD, std::nanf("")), groups(size_t(HW) * 4 * J), planes(groups.size());
  for (long p = 0; p < HW; ++p) {
    const float* e = &c.extra[size_t(p) * C];
    float* d = &dense[size_t(p) * CD];
    for (int k = 0; k < 3; ++k) d[k] = e[c.lay.base_color() + k];
    d[5] = e[c.lay.base_opacity()];
    for (int j = 0; j < J; ++j)
      for (int k = 0; k < 4; ++k) {
        const float g = e[k < 3 ? c.lay.color(j) + k : c.lay.opacity(j)] - d[k < 3 ? k : 5];
        groups[(size_t(p) * J + j) * 4 + k] = g;
        planes[(size_t(j) * HW + p) * 4 + k] = g;
      }
  }
  const ObjectRenders inter = ObjectRenders::sparse(dense.data(), CD, 5, groups.data(), J);
  const ObjectRenders planar = ObjectRenders::sparse(dense.data(), CD, 5, planes.data(), J, HW);
  // The planes as the renderer leaves them with group_live_tiles: only the flagged tiles written (6 x 6 pixels
  // here, so tiles cut boxes, crops and bands), the others' memory NaN. Flagged: every tile where the object's
  // difference has a bit set, and every 5th of the others (the renderer flags where the object has Gaussians).
  constexpr int kTile = 6;
  const int tx = (c.W + kTile - 1) / kTile, tiles = tx * ((c.H + kTile - 1) / kTile);
  std::vector<uint8_t> live(size_t(J) * tiles, 0);
  for (int j = 0; j < J; ++j)
    for (long p = 0; p < HW; ++p)
      for (int k = 0; k < 4; ++k)
        if (std::bit_cast<uint32_t>(planes[(size_t(j) * HW + p) * 4 + k]) != 0)
          live[size_t(j) * tiles + (p / c.W / kTile) * tx + p % c.W / kTile] = 1;
  std::vector<float> unwritten = planes;
  int zero_tiles = 0;
  for (int j = 0; j < J; ++j)
    for (int t = 0; t < tiles; ++t) {
      uint8_t& f = live[size_t(j) * tiles + t];
      if (!f && ++zero_tiles % 5 == 0) f = 1;
    }
  for (int j = 0; j < J; ++j)
    for (long p = 0; p < HW; ++p)
      if (!live[size_t(j) * tiles + (p / c.W / kTile) * tx + p % c.W / kTile])
        std::fill_n(&unwritten[(size_t(j) * HW + p) * 4], 4, std::nanf(""));
  ASSERT_GT(zero_tiles, 10);
  const ObjectRenders flagged =
      ObjectRenders::sparse(dense.data(), CD, 5, unwritten.data(), J, HW).with_live_tiles(live.data(), kTile, c.W, c.H);
  for (double frac : {0.8, 0.05})  // (0.05: objects whose crop is large are scored over the whole image)
    for (bool bro : {true, false})
      for (bool boxes : {true, false}) {
        HybridConfig cfg;
        cfg.use_bro = bro;
        ObjectLosses a(cfg, {.boxes = boxes, .max_box_fraction = frac}),
            b(cfg, {.boxes = boxes, .max_box_fraction = frac});
        std::vector<float> ga(size_t(HW) * 3 * J, std::nanf("")), gb(ga.size(), std::nanf("")), sa(size_t(HW) * 3),
            sb(sa.size());
        const ObjectLossValues va = a(c.image, c.lab, inter, c.objs, {ga.data(), 3L * J, sa.data(), 3});
        for (const ObjectRenders* r : {&planar, &flagged}) {
          std::fill(gb.begin(), gb.end(), std::nanf(""));
          const ObjectLossValues vb = b(c.image, c.lab, *r, c.objs, {gb.data(), 3L * J, sb.data(), 3});
          const std::string tag = std::string(bro ? "BRO" : "no BRO") + (boxes ? ", boxes" : ", whole images") +
                                  ", fraction " + std::to_string(frac) + (r == &flagged ? ", flagged tiles" : "");
          EXPECT_EQ(va.app, vb.app) << tag;
          EXPECT_EQ(va.bro, vb.bro) << tag;
          EXPECT_GT(va.app, 0) << tag;
          for (size_t i = 0; i < ga.size(); ++i)
            ASSERT_EQ(std::bit_cast<uint32_t>(ga[i]), std::bit_cast<uint32_t>(gb[i])) << tag << ", value " << i;
          for (size_t i = 0; i < sa.size(); ++i)
            ASSERT_EQ(std::bit_cast<uint32_t>(sa[i]), std::bit_cast<uint32_t>(sb[i])) << tag << ", sum " << i;
        }
      }
}

TEST(ObjectLossesBoxes, GradientsOverwriteTheColourChannelsAndLeaveOtherChannels) {
  // The colour channels of d_extra are written whatever they held (the bits of a zeroed buffer's), the others
  // (opacities, base) are not touched, and color_sum holds the colour gradients summed over the objects in order;
  // with boxes and over whole images.
  const Case c = synthetic(9);
  const HybridConfig cfg;
  for (bool boxes : {true, false}) {
    const Result ref = run(c, cfg, {.boxes = boxes});
    ObjectLosses losses(cfg, {.boxes = boxes});
    std::mt19937 rng(3);
    std::uniform_real_distribution<float> U(-1, 1);
    std::vector<float> init(c.extra.size()), d, sum(size_t(c.W) * c.H * 3, std::nanf(""));
    for (auto& v : init) v = U(rng);
    d = init;
    losses(c.image, c.lab, c.extra.data(), c.lay, c.objs, d.data(), sum.data());
    const int C = c.lay.total(), J = c.lay.J;
    for (size_t i = 0; i < d.size(); ++i) {
      const int ch = int(i % C);
      if (ch >= 3 * J) ASSERT_EQ(d[i], init[i]) << "channel " << ch;  // the other channel, opacities and base
      else ASSERT_EQ(std::bit_cast<uint32_t>(d[i]), std::bit_cast<uint32_t>(ref.d[i])) << "channel " << ch;
    }
    double scale = 0;
    for (size_t p = 0; p < size_t(c.W) * c.H; ++p)
      for (int k = 0; k < 3; ++k) {
        float s = 0.f;
        for (int j = 0; j < J; ++j) s += ref.d[p * C + c.lay.color(j) + k];
        ASSERT_EQ(std::bit_cast<uint32_t>(sum[p * 3 + k]), std::bit_cast<uint32_t>(s)) << "pixel " << p;
        scale = std::max(scale, double(std::abs(s)));
      }
    EXPECT_GT(scale, 0) << "boxes " << boxes;
  }
}

TEST(ObjectLossesBoxes, SparseGradientsDescribeTheDenseOnes) {
  const Case c = synthetic(10);
  for (const auto& [name, cfg] : configs()) {
    const Result dense = run(c, cfg, {});
    ObjectLosses losses(cfg);
    const ObjectLossValues v = losses(c.image, c.lab, c.extra.data(), c.lay, c.objs, nullptr);
    EXPECT_EQ(v.app, dense.v.app) << name;
    EXPECT_EQ(v.bro, dense.v.bro) << name;
    const ObjectGradients& g = losses.gradients();
    const int C = c.lay.total(), J = c.lay.J;
    ASSERT_TRUE(g.base_app && g.base_pred) << name;
    double err = 0;
    for (int y = 0; y < c.H; ++y)
      for (int x = 0; x < c.W; ++x)
        for (int j = 0; j < J; ++j)
          for (int ch = 0; ch < 3; ++ch) {
            const PixelBox& b = g.box[j];
            const size_t p = size_t(y) * c.W + x, i = p * 3 + ch;
            float want;
            if (x >= b.x0 && x < b.x1 && y >= b.y0 && y < b.y1) {
              want = g.own[j][(size_t(y - b.y0) * b.width() + (x - b.x0)) * 3 + ch];
            } else {
              want = g.app_scale * g.base_app[i];
              if (g.base_unit) want += g.bro_scale[j] * g.base_unit[i] - g.proj[j] * g.base_pred[i];
            }
            err = std::max(err, double(std::abs(want - dense.d[p * C + c.lay.color(j) + ch])));
          }
    EXPECT_LE(err, 1e-9) << name;
  }
}

// A box one pixel short of the dependency radius misses gradient terms (SSIM's tail at radius 10; with a 21-pixel
// band kernel eq. 14's differences at radius 11): the comparison must catch it, by more than 10x its tolerance.
TEST(ObjectLossesBoxes, ADilationOnePixelShortIsCaught) {
  const Case c = synthetic(11);
  HybridConfig wide;
  wide.bro_kernel = 21;
  for (const auto& [cfg, dep] : {std::pair{HybridConfig{}, 10}, std::pair{wide, 11}}) {
    const Result ref = run(c, cfg, {.boxes = false});
    const Result ok = run(c, cfg, {.max_box_fraction = 1.0, .dilation = dep});
    expect_same(ref, ok, "the dependency radius");
    const Result shrunk = run(c, cfg, {.max_box_fraction = 1.0, .dilation = dep - 1});
    double err, scale;
    grad_error(ref, shrunk, err, scale);
    EXPECT_GT(err, 1e-4 * scale) << "kernel " << cfg.bro_kernel;
  }
}

void expect_bitwise(const Result& ref, const Result& got, const std::string& what) {
  EXPECT_EQ(got.v.app, ref.v.app) << what;
  EXPECT_EQ(got.v.bro, ref.v.bro) << what;
  ASSERT_EQ(got.d.size(), ref.d.size());
  size_t differ = 0;
  for (size_t i = 0; i < ref.d.size(); ++i) differ += got.d[i] != ref.d[i];
  EXPECT_EQ(differ, 0u) << what;
}

// Bands of rows (object_losses.h): any banding of the base pair's and the objects' scoring, at any thread count,
// gives the values and gradients of scoring each in one piece, bitwise (bands of 1 row up to one band, crops of
// the background and of small objects, bands that cut through objects' boxes).
TEST(ObjectLossesBoxes, BandsOfRowsChangeNothingBitwise) {
  const Case c = synthetic(12);
  HybridConfig wide;
  wide.bro_kernel = 21;
  wide.bro_scale_invariant = false;
  for (const auto& [name, cfg] :
       {std::pair{std::string("default"), HybridConfig{}}, std::pair{std::string("wide"), wide}}) {
    for (double frac : {0.8, 1.0}) {
      omp_set_num_threads(1);
      const Result one = run(c, cfg, {.max_box_fraction = frac, .band_rows = 1000});
      const Result ref = run(c, cfg, {.boxes = false});
      expect_same(ref, one, name + " one band");
      for (int rows : {1, 4, 7, 25}) {
        const std::string what = name + " bands of " + std::to_string(rows) + " rows";
        expect_bitwise(one, run(c, cfg, {.max_box_fraction = frac, .band_rows = rows}), what);
        omp_set_num_threads(3);
        expect_bitwise(one, run(c, cfg, {.max_box_fraction = frac, .band_rows = rows}), what + ", 3 threads");
        omp_set_num_threads(1);
      }
      for (int threads : {2, 3, 5, 16}) {  // the banding chosen by the thread count
        omp_set_num_threads(threads);
        expect_bitwise(one, run(c, cfg, {.max_box_fraction = frac}),
                       name + " at " + std::to_string(threads) + " threads");
      }
    }
  }
  omp_set_num_threads(omp_get_num_procs());
}

// The real path: object_channels() with the base channels, softmax-like q rows (one dominant label, the others
// at the row minimum; some rows all equal), composited by the renderer; far objects equal the base bitwise, so
// most objects get small boxes.
TEST(ObjectLossesBoxes, RenderedObjectChannelsMatchTheWholeImageScoring) {
  const int W = 128, H = 96, L = 6, per = 60, N = L * per + 40;
  std::mt19937 rng(21);
  std::uniform_real_distribution<float> U(0, 1);
  render::Camera cam;
  cam.width = W;
  cam.height = H;
  cam.fx = cam.fy = 90;
  cam.cx = W / 2.f;
  cam.cy = H / 2.f;
  // Object l's Gaussians cluster around a centre (the background, label 0, spreads over the image); the last 40
  // rows are unobserved (q uniform: every label at the row minimum).
  const float centres[L][2] = {{0, 0}, {-0.9f, -0.6f}, {0.8f, -0.5f}, {-0.2f, 0.5f}, {1.2f, 0.75f}, {-1.3f, 0.8f}};
  std::vector<float> mean, log_scale, quat, opacity, colors, q(size_t(N) * L);
  for (int i = 0; i < N; ++i) {
    const int l = i < L * per ? i / per : -1;
    const float spread = l <= 0 ? 1.5f : 0.15f;
    const float cx = l > 0 ? centres[l][0] : 0.f, cy = l > 0 ? centres[l][1] : 0.f;
    mean.insert(mean.end(), {cx + spread * (2 * U(rng) - 1), cy + spread * 0.7f * (2 * U(rng) - 1), 2.5f + U(rng)});
    const float s = std::log(0.03f + 0.05f * U(rng));
    log_scale.insert(log_scale.end(), {s, s + 0.2f * (U(rng) - 0.5f), s});
    quat.insert(quat.end(), {1, 0.2f * (U(rng) - 0.5f), 0.2f * (U(rng) - 0.5f), 0.1f});
    opacity.push_back(3 * U(rng) - 1);
    colors.insert(colors.end(), {U(rng), U(rng), U(rng)});
    const float top = l >= 0 ? 0.6f + 0.3f * U(rng) : 1.f / L, rest = (1 - top) / (L - 1);
    for (int k = 0; k < L; ++k) q[size_t(i) * L + k] = l < 0 ? 1.f / L : (k == l ? top : rest);
  }
  Case c;
  c.W = W;
  c.H = H;
  c.objs = {0, 1, 2, 3, 4, 5};
  c.lay = ObjectLayout{L, 0, true};
  const int C = c.lay.total();
  std::vector<float> ch(size_t(N) * C);
  object_channels(N, L, c.lay, c.objs.data(), q.data(), colors.data(), ch.data());
  render::GaussianRenderer r;
  render::GaussianInputs in;
  in.n = N;
  in.mean = mean.data();
  in.log_scale = log_scale.data();
  in.quat = quat.data();
  in.opacity_logit = opacity.data();
  in.colors = colors.data();
  in.extra = ch.data();
  in.num_extra = C;
  render::RenderSettings rs;
  rs.want_depth = false;
  render::RenderOutputs out;
  r.forward(cam, in, rs, out);
  c.extra = out.extra;
  // Labels: each object's pixels where it dominates the render's opacity, the rest background.
  c.image = Image(W, H, 3);
  for (auto& v : c.image.px) v = U(rng);
  c.lab = LabelMap(W, H, 0);
  for (size_t p = 0; p < size_t(W) * H; ++p)
    for (int j = 1; j < L; ++j)
      if (c.extra[p * C + c.lay.opacity(j)] > 0.4f) c.lab.v[p] = uint16_t(j);
  for (const auto& [name, cfg] : configs()) {
    const Result ref = run(c, cfg, {.boxes = false});
    const Result def = run(c, cfg, {});
    expect_same(ref, def, name + " rendered");
    expect_same(ref, run(c, cfg, {.max_box_fraction = 1.0}), name + " rendered, all boxes");
    int small = 0;
    for (const PixelBox& b : def.boxes) small += b.area() < size_t(W) * H / 2;
    EXPECT_GE(small, 3) << name << ": the clustered objects should get small boxes";
    EXPECT_EQ(def.boxes[0].area(), size_t(W) * H) << name;  // the background spreads over the image
  }
}

// The helpers the box path adds: train::ssim_map (map, count, a null all-zero y) against train::ssim,
// train::ssim_map_rows against ssim_map, and bro_parts against bro_loss.
TEST(ObjectLossesBoxes, SsimMapAndBroPartsAgreeWithSsimAndBroLoss) {
  const int W = 37, H = 29, C = 3, n = W * H * C;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> U(0, 1);
  std::vector<float> x(n), y(n), zero(n, 0.f), g(n), gm(n), map(n), B(size_t(W) * H);
  for (auto& v : x) v = U(rng);
  for (auto& v : y) v = U(rng);
  for (auto& v : B) v = U(rng) < 0.3f ? 0.f : U(rng);
  train::SsimWorkspace<float> ws;
  for (const float* yy : {y.data(), zero.data()}) {
    const float s = train::ssim(x.data(), yy, H, W, C, g.data(), ws);
    // count = 4 n: the gradient of sum(map) / (4 n), a quarter of ssim()'s.
    const float sm = train::ssim_map(x.data(), yy, H, W, C, gm.data(), map.data(), 4.0 * n, ws);
    EXPECT_EQ(sm, s);
    double sum = 0;
    for (float v : map) sum += v;
    EXPECT_NEAR(sum / n, s, 1e-6);
    for (int i = 0; i < n; ++i) ASSERT_NEAR(gm[i], g[i] / 4, 1e-6f * std::abs(g[i]) + 1e-12f) << i;
  }
  // A null y is an all-zero one.
  const float s0 = train::ssim(x.data(), zero.data(), H, W, C, g.data(), ws);
  EXPECT_EQ(train::ssim_map(x.data(), static_cast<const float*>(nullptr), H, W, C, gm.data(), map.data(), double(n),
                            ws),
            s0);
  for (int i = 0; i < n; ++i) ASSERT_NEAR(gm[i], g[i], 1e-6f * std::abs(g[i]) + 1e-12f) << i;
  // ssim_map_rows: rows [y0, y1) bitwise ssim_map's (bands at the edges, inside, one row, the whole image).
  for (const float* yy : {static_cast<const float*>(y.data()), static_cast<const float*>(nullptr)}) {
    train::ssim_map(x.data(), yy, H, W, C, gm.data(), map.data(), 3.0 * n, ws);
    for (auto [y0, y1] : {std::pair{0, 4}, std::pair{7, 8}, std::pair{10, 21}, std::pair{22, H}, std::pair{0, H}}) {
      std::vector<float> gr(n, -7.f), mr(n, -7.f);
      train::SsimWorkspace<float> wr;
      train::ssim_map_rows(x.data(), yy, H, W, C, y0, y1, gr.data(), mr.data(), 3.0 * n, wr);
      for (int i = y0 * W * C; i < y1 * W * C; ++i) {
        ASSERT_EQ(gr[i], gm[i]) << "rows " << y0 << "-" << y1 << " value " << i;
        ASSERT_EQ(mr[i], map[i]) << "rows " << y0 << "-" << y1 << " value " << i;
      }
      for (int i = 0; i < y0 * W * C; ++i) ASSERT_EQ(gr[i], -7.f);  // rows above the band: not written
    }
  }
  // bro_parts: sum num / (C sum wsum + eps) is eq. 14 and unit * scale / (C sum wsum + eps) its gradient.
  std::vector<double> wsum(size_t(W) * H), num(size_t(W) * H);
  std::vector<float> unit(n), gb(n, 0.f);
  bro_parts(x.data(), y.data(), C, B.data(), H, W, wsum.data(), num.data(), unit.data());
  const float eps = 1e-6f, scale = 0.7f;
  const float L = bro_loss(x.data(), y.data(), C, C, B.data(), H, W, eps, gb.data(), scale);
  double ws_total = 0, num_total = 0;
  for (size_t p = 0; p < wsum.size(); ++p) ws_total += wsum[p], num_total += num[p];
  EXPECT_NEAR(ws_total, band_weight_total(B.data(), H, W), 1e-9 * ws_total);
  const double den = C * ws_total + eps;
  EXPECT_NEAR(num_total / den, L, 1e-6 * L);
  double err = 0, mx = 0;
  for (int i = 0; i < n; ++i) {
    err = std::max(err, std::abs(unit[i] * scale / den - gb[i]));
    mx = std::max(mx, double(std::abs(gb[i])));
  }
  ASSERT_GT(mx, 0);
  EXPECT_LE(err, 1e-6 * mx);
}

TEST(ObjectLossesBoxes, SsimOnPartOfARowAndTheTargetsSupportIsTheFullPassesBitwise) {
  // ssim_map_rows for output columns [x0, x1) and with `ys` (where y may be non-zero; y's passes run on and near
  // it only) against the full passes, on a y that is zero outside the box: the map and the gradient there bitwise
  // (a zero may differ in its sign, which == ignores), gradients elsewhere not written; boxes inside the image, at
  // its edges and corners, one pixel wide or high, larger than the image, empty; bands of rows and of columns that
  // cross the box or miss it, at the image's edges, one wide.
  const int W = 41, H = 33, C = 3, n = W * H * C;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> U(0, 1);
  std::vector<float> x(n), y(n);
  for (auto& v : x) v = U(rng);
  const train::SsimSupport boxes[] = {{12, 9, 25, 20}, {0, 0, 7, 6},     {30, 25, 41, 33}, {17, 3, 18, 30},
                                      {2, 16, 39, 17}, {-5, -5, 60, 60}, {10, 10, 10, 20}, {0, 0, 41, 33}};
  const std::pair<int, int> rows[] = {{0, H}, {0, 4}, {8, 21}, {26, H}, {15, 16}};
  const std::pair<int, int> cols[] = {{0, W}, {0, 9}, {13, 30}, {33, W}, {20, 21}, {4, 37}};
  for (const train::SsimSupport& b : boxes) {
    for (int yy = 0; yy < H; ++yy)
      for (int xx = 0; xx < W; ++xx)
        for (int c = 0; c < C; ++c) {
          const bool in = xx >= b.x0 && xx < b.x1 && yy >= b.y0 && yy < b.y1;
          y[(size_t(yy) * W + xx) * C + c] = in ? U(rng) : 0.f;
        }
    for (auto [y0, y1] : rows) {
      std::vector<float> g0(n, -7.f), m0(n, -7.f);
      train::SsimWorkspace<float> w0, w1;
      train::ssim_map_rows(x.data(), y.data(), H, W, C, y0, y1, g0.data(), m0.data(), 2.0 * n, w0);
      for (auto [x0, x1] : cols) {
        std::vector<float> g1(n, -7.f), m1(n, -7.f);
        train::ssim_map_rows(x.data(), y.data(), H, W, C, y0, y1, g1.data(), m1.data(), 2.0 * n, w1, b, x0, x1);
        for (int r = 0; r < H; ++r)
          for (int xx = 0; xx < W; ++xx)
            for (int c = 0; c < C; ++c) {
              const size_t i = (size_t(r) * W + xx) * C + c;
              const bool out = r >= y0 && r < y1 && xx >= x0 && xx < x1;
              ASSERT_EQ(g1[i], out ? g0[i] : -7.f) << "box " << b.x0 << "," << b.y0 << " rows " << y0 << "-" << y1
                                                   << " columns " << x0 << "-" << x1 << " at " << xx << "," << r;
              if (out) {
                ASSERT_EQ(m1[i], m0[i]) << "box " << b.x0 << "," << b.y0 << " at " << xx << "," << r;
              }
            }
      }
    }
  }
}

// train::ssim_rows_streamed, as score_crop uses it with a ring of crop rows: rows of x and y first asked for in
// increasing order, one after the other, none asked for more than 10 rows before the latest; the sink's rows
// y0 .. y1 - 1 in order, each bitwise ssim_map's (gradient on the output columns, map 5 columns further).
TEST(ObjectLossesBoxes, SsimStreamedAsksForRowsInOrderAndHandsOutSsimMapsRows) {
  const int W = 23, H = 40, C = 3, n = W * H * C, L = W * C;
  std::mt19937 rng(13);
  std::uniform_real_distribution<float> U(0, 1);
  std::vector<float> x(n), y(n), g(n), map(n);
  for (auto& v : x) v = U(rng);
  for (auto& v : y) v = U(rng);
  train::SsimWorkspace<float> ws, wsr;
  train::ssim_map(x.data(), y.data(), H, W, C, g.data(), map.data(), 2.0 * n, ws);
  for (const auto& rows : {std::pair{0, H}, std::pair{12, 27}, std::pair{30, H}, std::pair{0, 3}, std::pair{19, 20}})
    for (const auto& cols : {std::pair{0, W}, std::pair{6, 15}}) {
      const int y0 = rows.first, y1 = rows.second, x0 = cols.first, x1 = cols.second;  // (captured below)
      const std::string what = "rows " + std::to_string(y0) + "-" + std::to_string(y1) + " columns " +
                               std::to_string(x0) + "-" + std::to_string(x1);
      int latest = -1, next_sink = y0;
      auto asked = [&](int r) {
        if (r > latest) {
          EXPECT_EQ(r, latest < 0 ? std::max(0, y0 - 10) : latest + 1) << what;
          latest = r;
        }
        EXPECT_GE(r, latest - 10) << what;
        EXPECT_LT(r, std::min(H, y1 + 10)) << what;
      };
      train::ssim_rows_streamed<float>(
          [&](int r) {
            asked(r);
            return &x[size_t(r) * L];
          },
          [&](int r) {
            asked(r);
            return &y[size_t(r) * L];
          },
          H, W, C, y0, y1, 2.0 * n, wsr,
          [&](int r, const float* gr, const float* mr) {
            ASSERT_EQ(r, next_sink++) << what;
            for (int j = x0 * C; j < x1 * C; ++j) ASSERT_EQ(gr[j], g[size_t(r) * L + j]) << what << " row " << r;
            for (int j = std::max(0, x0 - 5) * C; j < std::min(W, x1 + 5) * C; ++j)
              ASSERT_EQ(mr[j], map[size_t(r) * L + j]) << what << " row " << r;
          },
          {}, x0, x1);
      EXPECT_EQ(next_sink, y1) << what;
    }
}

TEST(ObjectLossesBoxes, BroPartsOnThinImagesAndReusedBuffers) {
  // bro_parts on images one pixel wide or high, two wide, and 1 x 1, with C = 3 and 1, writing into a buffer full
  // of earlier values (every value is overwritten): its terms and gradient are eq. 14's (bro_loss with every
  // term's gradient at scale 1 and the normaliser multiplied back).
  std::mt19937 rng(9);
  std::uniform_real_distribution<float> U(0, 1);
  for (auto [W, H] : {std::pair{1, 7}, std::pair{7, 1}, std::pair{2, 5}, std::pair{1, 1}, std::pair{3, 2}})
    for (int C : {3, 1}) {
      const int n = W * H * C;
      std::vector<float> x(n), y(n), B(size_t(W) * H), unit(n, std::nanf("")), gb(n, 0.f);
      for (auto& v : x) v = U(rng);
      for (auto& v : y) v = U(rng);
      for (auto& v : B) v = 0.2f + 0.8f * U(rng);
      std::vector<double> wsum(size_t(W) * H), num(size_t(W) * H);
      bro_parts(x.data(), y.data(), C, B.data(), H, W, wsum.data(), num.data(), unit.data());
      const float eps = 1e-6f;
      const double band = band_weight_total(B.data(), H, W);
      const float L = bro_loss(x.data(), y.data(), C, C, B.data(), H, W, eps, gb.data(), 1.f);
      double ws_total = 0, num_total = 0;
      for (size_t p = 0; p < wsum.size(); ++p) ws_total += wsum[p], num_total += num[p];
      EXPECT_NEAR(ws_total, band, 1e-9 * (band + 1)) << W << "x" << H << " C " << C;
      const double den = C * band + eps;
      EXPECT_NEAR(num_total / den, L, 1e-6 * (L + 1e-6)) << W << "x" << H << " C " << C;
      for (int i = 0; i < n; ++i)
        ASSERT_NEAR(unit[i] / den, gb[i], 1e-6 * (std::abs(gb[i]) + 1e-3)) << W << "x" << H << " C " << C << " " << i;
    }
}

TEST(ObjectLossesBoxes, RendersAndObjectsOfDifferentCountsAreRefused) {
  // An ObjectRenders of J objects with a list of another length: a one-line error, nothing scored.
  const Case c = synthetic(4);
  const ObjectRenders r = ObjectRenders::interleaved(c.extra.data(), c.lay);
  std::vector<int> more = c.objs;
  more.push_back(more.back() + 1);
  ObjectLosses losses{HybridConfig{}};
  std::vector<float> g(size_t(c.W) * c.H * 3 * more.size());
  const ObjectGradOut out{g.data(), 3L * long(more.size()), nullptr, 3};
  EXPECT_THROW(losses(c.image, c.lab, r, more, out), Error);
}
