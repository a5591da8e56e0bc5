// Pixel-weight maps given as one label image (RenderSettings::pixel_labels and pixel_label_ids, as the hybrid
// method's SCL anchors pass them) are the float maps of their hard masks: the same weight sums and gradients, bit
// for bit, and bad settings fail with one line.
#include <gtest/gtest.h>

#include <random>
#include <string>
#include <vector>

#include "core/error.h"
#include "render/raster_isa.h"
#include "render/renderer.h"
#include "render_ref.h"
#include "render_run.h"

namespace hgs::render::test {
namespace {

// Labels 0..6 in blocks 5 pixels wide and 16 high, shifted per block row, so most 8-pixel batches see one or two
// labels. [H, W]
std::vector<uint16_t> label_image(int W, int H) {
  std::vector<uint16_t> lab(size_t(W) * H);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) lab[size_t(y) * W + x] = uint16_t((x / 5 + 3 * (y / 16)) % 7);
  return lab;
}

template <class T>
struct Run {
  RenderOutputsT<T> out;
  ProjectedGradsT<T> pg;
};

// Renders s with settings `set` and runs the backward of random upstream gradients on rgb, alpha and the weight
// sums (the same seed for every call).
template <class T>
Run<T> render(const Scene& s, const RenderSettings& set, int J) {
  Run<T> r;
  RendererT<T> ren;
  std::vector<std::vector<T>> store;
  ren.preprocess(s.cam, s.inputs<T>(store));
  ChannelsT<T> ch;
  ren.composite(ch, set, r.out);
  std::mt19937 rng(11);
  auto weights = [&](size_t n) {
    std::vector<T> w;
    for (double v : hgs::test::random_weights(n, rng)) w.push_back(T(v));
    return w;
  };
  const std::vector<T> wr = weights(r.out.rgb.size()), wa = weights(r.out.alpha.size()), ww = weights(size_t(s.n) * J);
  OutputGradsT<T> d;
  d.rgb = wr.data();
  d.alpha = wa.data();
  d.weight_sums = ww.data();
  ren.composite_backward(d, r.pg);
  return r;
}

template <class T>
void compare_labels_and_maps(const std::vector<int>& ids) {
  SCOPED_TRACE("J = " + std::to_string(ids.size()));
  Scene s = random_scene(400, 69, 50, 17, 0.9, 0);  // 69 pixels wide: partial batches at the right edge
  const int W = s.cam.width, H = s.cam.height, J = int(ids.size());
  const std::vector<uint16_t> lab = label_image(W, H);
  std::vector<float> maps(size_t(J) * W * H, 0.f);
  for (int j = 0; j < J; ++j)
    for (size_t p = 0; p < lab.size(); ++p) maps[size_t(j) * lab.size() + p] = lab[p] == ids[j] ? 1.f : 0.f;
  RenderSettings floats = s.settings, labels = s.settings;
  floats.pixel_weights = maps.data();
  floats.num_pixel_weights = J;
  labels.pixel_labels = lab.data();
  labels.pixel_label_ids = ids.data();
  labels.num_pixel_weights = J;
  on_each_isa([&] {
    const Run<T> a = render<T>(s, floats, J), b = render<T>(s, labels, J);
    EXPECT_GT(max_abs(a.out.weight_sums), 0.0);
    EXPECT_GT(max_abs(a.pg.opacity), 0.0);
    for (auto [x, y, what] : {std::tuple{&a.out.rgb, &b.out.rgb, "rgb"},
                              {&a.out.weight_sums, &b.out.weight_sums, "weight sums"},
                              {&a.pg.mean2d, &b.pg.mean2d, "mean2d"},
                              {&a.pg.conic, &b.pg.conic, "conic"},
                              {&a.pg.opacity, &b.pg.opacity, "opacity"},
                              {&a.pg.colors, &b.pg.colors, "colors"}})
      EXPECT_TRUE(bitwise_equal(*x, *y)) << what << ": max difference " << max_abs_diff(*x, *y);
  });
}

TEST(RenderPixelLabels, LabelImageIsBitwiseItsFloatMaps) {
  // Labels 3, 1 and 0, and 9, which no pixel has (its sums are 0).
  compare_labels_and_maps<float>({3, 1, 9, 0});
  compare_labels_and_maps<double>({3, 1, 9, 0});
  // More than 32 maps (every map visited in every batch): the labels 0..6 five times over.
  std::vector<int> many;
  for (int j = 0; j < 35; ++j) many.push_back(j % 7);
  compare_labels_and_maps<float>(many);
}

TEST(RenderPixelLabels, BadSettingsFailWithOneLine) {
  Scene s = random_scene(50, 32, 24, 5, 0.9, 0);
  const std::vector<uint16_t> lab(size_t(32) * 24, 1);
  const std::vector<float> maps(size_t(32) * 24, 1.f);
  const std::vector<int> ids = {1, -2}, good = {1, 2};
  RendererT<float> ren;
  std::vector<std::vector<float>> store;
  ren.preprocess(s.cam, s.inputs<float>(store));
  RenderOutputsT<float> out;
  auto fails = [&](const RenderSettings& set, const std::string& what) {
    try {
      ren.composite(ChannelsT<float>{}, set, out);
      ADD_FAILURE() << "no error for " << what;
    } catch (const Error& e) {
      const std::string m = e.what();
      EXPECT_EQ(m.find('\n'), std::string::npos) << m;
      EXPECT_NE(m.find("pixel"), std::string::npos) << m;
    }
  };
  RenderSettings none;  // J maps but neither the maps nor the labels
  none.num_pixel_weights = 2;
  fails(none, "no maps");
  RenderSettings no_ids = none;  // labels without their ids
  no_ids.pixel_labels = lab.data();
  fails(no_ids, "labels without ids");
  RenderSettings negative = no_ids;
  negative.pixel_label_ids = ids.data();
  fails(negative, "a negative label id");
  RenderSettings both = negative;
  both.pixel_label_ids = good.data();
  both.pixel_weights = maps.data();
  fails(both, "maps and labels");
}

}  // namespace
}  // namespace hgs::render::test
