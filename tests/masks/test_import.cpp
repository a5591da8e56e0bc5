// `hgs masks import` on tiny hand-made inputs of every format: round trips through the scene loader, every
// bad-input error, and no partial output.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "core/npy.h"
#include "masks/flatten.h"
#include "masks/import.h"
#include "masks/png_index.h"
#include "masks/sources.h"
#include "masks_test_util.h"
#include "scene/scene.h"
#include "test_util.h"

using namespace hgs;
using namespace hgs::masks;
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

constexpr int W = 6, H = 4;

std::vector<uint8_t> box(int x0, int y0, int x1, int y1) {  // inclusive
  std::vector<uint8_t> b(W * H, 0);
  for (int y = y0; y <= y1; ++y)
    for (int x = x0; x <= x1; ++x) b[y * W + x] = 1;
  return b;
}

json sam_entry(const std::vector<uint8_t>& b, double iou, double stab, bool string_counts) {
  Rle r = rle_encode(b, W, H);
  json counts = string_counts ? json(rle_counts_to_string(r.counts)) : json(r.counts);
  return {{"segmentation", {{"size", {H, W}}, {"counts", counts}}},
          {"area", rle_area(r)},
          {"bbox", {0, 0, 1, 1}},
          {"predicted_iou", iou},
          {"stability_score", stab},
          {"point_coords", {{0, 0}}},
          {"crop_box", {0, 0, W, H}}};
}

// Three views; the expected flattened label map of view a for the masks below.
struct Fixture {
  test::TempDir t;
  fs::path scene = t / "scene";
  Fixture() { test::make_tiny_scene(scene, {"a.png", "b.jpg", "sub/c.png"}, W, H); }
  std::vector<std::vector<uint8_t>> masks_a = {box(0, 0, 4, 3), box(0, 0, 1, 1), box(3, 1, 5, 2)};
  ImportOptions opt(const std::string& from, const fs::path& dir) {
    ImportOptions o;
    o.scene = scene;
    o.from = from;
    o.dir = dir;
    o.progress = false;
    return o;
  }
  void write_sam_json(const fs::path& dir) {
    json a = json::array({sam_entry(masks_a[0], 0.95, 0.9, true), sam_entry(masks_a[1], 0.8, 0.99, false),
                          sam_entry(masks_a[2], 0.9, 0.97, true)});
    atomic_write_text(dir / "a.json", a.dump());
    atomic_write_text(dir / "sub" / "c.json", json::array({sam_entry(box(2, 2, 3, 3), 0.9, 0.9, true)}).dump());
  }
  LabelMap expected_a() {  // smallest wins: mask 1 (4 px) over mask 2 (6 px) over mask 0 (20 px)
    LabelMap m(W, H);
    for (int y = 0; y < H; ++y)
      for (int x = 0; x < W; ++x) {
        const size_t p = y * W + x;
        m.v[p] = masks_a[1][p] ? 2 : masks_a[2][p] ? 3 : masks_a[0][p] ? 1 : 0;
      }
    return m;
  }
};

void expect_no_leftovers(const fs::path& scene) {
  for (auto& e : fs::directory_iterator(scene))
    EXPECT_NE(e.path().filename().string()[0], '.') << "left behind: " << e.path();
}

}  // namespace

TEST(Import, SamJsonRoundTripThroughTheSceneLoader) {
  Fixture f;
  f.write_sam_json(f.t / "sam");
  ImportSummary s = import_masks(f.opt("sam-json", f.t / "sam"));
  EXPECT_EQ(s.imported, 2);
  EXPECT_EQ(s.masks, 4u);
  ASSERT_EQ(s.missing.size(), 1u);
  EXPECT_EQ(s.missing[0], "b.jpg");
  Scene sc = load_scene(f.scene);
  ASSERT_EQ(sc.views[0].name, "a.png");
  auto m = sc.load_mask(0);
  ASSERT_TRUE(m);
  EXPECT_EQ(m->v, f.expected_a().v);
  auto conf = sc.load_confidence(0);
  ASSERT_TRUE(conf);
  EXPECT_FLOAT_EQ((*conf)[0], float(0.8 * 0.99));          // (0,0): mask 2
  EXPECT_FLOAT_EQ((*conf)[1 * W + 4], float(0.9 * 0.97));  // (4,1): mask 3
  EXPECT_FLOAT_EQ((*conf)[0 * W + 3], float(0.95 * 0.9));  // (3,0): mask 1
  EXPECT_FLOAT_EQ((*conf)[0 * W + 5], 1.f);                // (5,0): none
  EXPECT_FALSE(sc.load_mask(1));
  EXPECT_TRUE(sc.load_mask(2));  // sub/c.png from sub/c.json
  json meta = json::parse(read_file_text(f.scene / "masks" / "import.json"));
  EXPECT_EQ(meta["format"], "sam-json");
  EXPECT_EQ(meta["views"]["a"]["masks"][1]["visible"], 4);
  EXPECT_EQ(meta["views"]["a"]["masks"][0]["area"], 20);
  EXPECT_FALSE(fs::exists(f.scene / "masks" / "objects.json"));
  expect_no_leftovers(f.scene);
}

TEST(Import, SamPngFolderGivesTheSameAsSamJson) {
  Fixture f;
  const fs::path dir = f.t / "amg" / "a";
  std::string csv =
      "id,area,bbox_x0,bbox_y0,bbox_w,bbox_h,point_input_x,point_input_y,predicted_iou,stability_score,crop_box_x0,"
      "crop_box_y0,crop_box_w,crop_box_h\n";
  const double iou[3] = {0.95, 0.8, 0.9}, stab[3] = {0.9, 0.99, 0.97};
  for (int i = 0; i < 3; ++i) {
    Image im(W, H, 1);
    for (size_t p = 0; p < im.px.size(); ++p) im.px[p] = f.masks_a[i][p] ? 1.f : 0.f;
    save_png(dir / (std::to_string(i) + ".png"), im);
    csv += fmt::format("{},0,0,0,1,1,0,0,{},{},0,0,{},{}\n", i, iou[i], stab[i], W, H);
  }
  atomic_write_text(dir / "metadata.csv", csv);
  import_masks(f.opt("sam-png", f.t / "amg"));
  Scene sc = load_scene(f.scene);
  EXPECT_EQ(sc.load_mask(0)->v, f.expected_a().v);
  EXPECT_FLOAT_EQ((*sc.load_confidence(0))[0], float(0.8 * 0.99));
}

TEST(Import, Sam2PaletteAndGreyLabelMaps) {
  Fixture f;
  LabelMap a(W, H), c(W, H);
  for (size_t p = 0; p < a.v.size(); ++p) a.v[p] = uint16_t(p % 4), c.v[p] = uint16_t(p % 3 ? 300 : 2);
  std::vector<uint8_t> pal = {0, 0, 0, 128, 0, 0, 0, 128, 0, 128, 128, 0};  // DAVIS-like
  auto png = encode_palette_png(a, pal);
  atomic_write_bytes(f.t / "sam2" / "a.png", png.data(), png.size());
  save_label_png(f.t / "sam2" / "sub" / "c.png", c);  // 16-bit grey
  import_masks(f.opt("sam2-png", f.t / "sam2"));
  Scene sc = load_scene(f.scene);
  EXPECT_EQ(sc.load_mask(0)->v, a.v);
  EXPECT_EQ(sc.load_mask(2)->v, c.v);
  EXPECT_FALSE(sc.load_confidence(0));
}

TEST(Import, LangSplatLevelsFeaturesAndResampling) {
  Fixture f;
  // Seg maps at half resolution (LangSplat resizes): [4, 2, 3]; features [M = 5, D = 2].
  const int h = 2, w = 3, D = 2, M = 5;
  std::vector<float> seg(4 * h * w, -1.f);
  const float lvl0[6] = {0, 1, -1, 1, 1, -1}, lvl2[6] = {3, 3, 4, 4, -1, 3};
  for (int p = 0; p < 6; ++p) seg[p] = lvl0[p], seg[2 * h * w + p] = lvl2[p];
  std::vector<float> feat = {1, 0, 0, 1, 5, 5, 2, 0, 0, 2};
  test::write_f32(f.t / "ls" / "a_s.npy", {4, size_t(h), size_t(w)}, seg);
  test::write_f32(f.t / "ls" / "a_f.npy", {size_t(M), size_t(D)}, feat);
  ImportOptions o = f.opt("langsplat", f.t / "ls");
  o.level = "m";
  o.level_given = true;
  o.feature_stride = 1;
  import_masks(o);
  Scene sc = load_scene(f.scene);
  LabelMap m = *sc.load_mask(0);
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) EXPECT_EQ(m.at(x, y), uint16_t(lvl2[(y / 2) * w + x / 2] + 1)) << x << "," << y;
  int gh, gw, d;
  auto grid = sc.load_feature_grid(0, gh, gw, d);
  ASSERT_EQ(gh, h);
  ASSERT_EQ(gw, w);
  ASSERT_EQ(d, D);
  for (int p = 0; p < 6; ++p)
    for (int k = 0; k < D; ++k) EXPECT_FLOAT_EQ((*grid)[p * D + k], lvl2[p] < 0 ? 0.f : feat[int(lvl2[p]) * D + k]);
  // Stride 2 at level default: cell (0,0) covers indices 0, 1, 1, 1 -> (1 * f0 + 3 * f1) / 4.
  o.level = "default";
  o.feature_stride = 2;
  o.force = true;
  import_masks(o);
  grid = sc.load_feature_grid(0, gh, gw, d);
  ASSERT_EQ(gh, 1);
  ASSERT_EQ(gw, 2);
  EXPECT_FLOAT_EQ((*grid)[0], 0.25f);
  EXPECT_FLOAT_EQ((*grid)[1], 0.75f);
  EXPECT_FLOAT_EQ((*grid)[2], 0.f);  // cell (1,0): nothing labelled
  json meta = json::parse(read_file_text(f.scene / "masks" / "import.json"));
  EXPECT_EQ(meta["level"], "default");
}

TEST(Import, BadInputNamesTheFileAndLeavesNothing) {
  Fixture f;
  // 1. RLE whose size does not match the image.
  {
    std::vector<uint8_t> b(3 * 3, 1);
    Rle r = rle_encode(b, 3, 3);
    json j = json::array({{{"segmentation", {{"size", {3, 3}}, {"counts", rle_counts_to_string(r.counts)}}}}});
    atomic_write_text(f.t / "bad1" / "a.json", j.dump());
    std::string e = test::error_of([&] { import_masks(f.opt("sam-json", f.t / "bad1")); });
    EXPECT_NE(e.find("a.json: mask 0: RLE size 3x3 (h x w) does not match the image's 4x6"), std::string::npos) << e;
  }
  // 2. Counts that overrun.
  {
    json j = json::array({sam_entry(box(0, 0, 1, 1), 0.9, 0.9, true)});
    j[0]["segmentation"]["counts"] = json::array({10, 20});
    atomic_write_text(f.t / "bad2" / "a.json", j.dump());
    std::string e = test::error_of([&] { import_masks(f.opt("sam-json", f.t / "bad2")); });
    EXPECT_NE(e.find("a.json: mask 0: RLE counts overrun"), std::string::npos) << e;
  }
  // 3. Masks for an image that is not in the COLMAP model (a good file beside it must not be imported).
  {
    f.write_sam_json(f.t / "bad3");
    atomic_write_text(f.t / "bad3" / "zz.json", "[]");
    std::string e = test::error_of([&] { import_masks(f.opt("sam-json", f.t / "bad3")); });
    EXPECT_NE(e.find("zz.json: masks for an image that is not in the COLMAP model"), std::string::npos) << e;
  }
  // 4. A LangSplat index beyond the feature list.
  {
    test::write_f32(f.t / "bad4" / "a_s.npy", {4, 2, 3}, std::vector<float>(24, 2.f));
    test::write_f32(f.t / "bad4" / "a_f.npy", {2, 3}, std::vector<float>(6, 0.f));
    std::string e = test::error_of([&] { import_masks(f.opt("langsplat", f.t / "bad4")); });
    EXPECT_NE(e.find("a_s.npy: index 2 at pixel (0, 0) of level 0 is beyond the feature list"), std::string::npos) << e;
  }
  // 5. A palette PNG without a palette.
  {
    auto png = encode_palette_png(LabelMap(W, H, 1), {});
    atomic_write_bytes(f.t / "bad5" / "sub" / "c.png", png.data(), png.size());
    std::string e = test::error_of([&] { import_masks(f.opt("sam2-png", f.t / "bad5")); });
    EXPECT_NE(e.find("c.png: palette PNG without a palette"), std::string::npos) << e;
  }
  EXPECT_FALSE(fs::exists(f.scene / "masks"));
  EXPECT_FALSE(fs::exists(f.scene / "features"));
  expect_no_leftovers(f.scene);
  // An amg folder whose PNG has the wrong size; --level with a format that has none.
  {
    atomic_write_text(f.t / "bad6" / "a" / "metadata.csv", "id,area,predicted_iou,stability_score\n0,1,0.9,0.9\n");
    save_png(f.t / "bad6" / "a" / "0.png", Image(3, 3, 1, 1.f));
    std::string e = test::error_of([&] { import_masks(f.opt("sam-png", f.t / "bad6")); });
    EXPECT_NE(e.find("0.png: mask is 3x3 but the image is 6x4"), std::string::npos) << e;
    ImportOptions o = f.opt("sam-json", f.t / "bad1");
    o.level_given = true;
    EXPECT_NE(test::error_of([&] { import_masks(o); }).find("--level"), std::string::npos);
  }
}

TEST(Import, ExistingMasksNeedForceAndSurviveAFailure) {
  Fixture f;
  f.write_sam_json(f.t / "sam");
  import_masks(f.opt("sam-json", f.t / "sam"));
  const auto before = read_file_bytes(f.scene / "masks" / "a.png");
  EXPECT_NE(test::error_of([&] { import_masks(f.opt("sam-json", f.t / "sam")); }).find("pass --force"),
            std::string::npos);
  // A failing forced import keeps the old masks.
  atomic_write_text(f.t / "sam" / "sub" / "c.json", "[{\"segmentation\": {\"size\": [4, 6], \"counts\": \"T\"}}]");
  ImportOptions o = f.opt("sam-json", f.t / "sam");
  o.force = true;
  EXPECT_NE(test::error_of([&] { import_masks(o); }).find("c.json: mask 0"), std::string::npos);
  EXPECT_EQ(read_file_bytes(f.scene / "masks" / "a.png"), before);
  EXPECT_TRUE(fs::exists(f.scene / "masks" / "sub" / "c.png"));
  expect_no_leftovers(f.scene);
}
