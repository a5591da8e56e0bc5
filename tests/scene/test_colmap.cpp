#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <functional>

#include "core/error.h"
#include "core/fs.h"
#include "core/image.h"
#include "core/npy.h"
#include "scene/colmap.h"
#include "scene/scene.h"
#include "test_util.h"

using namespace hgs;
namespace fs = std::filesystem;

namespace {

ColmapModel sample_model() {
  ColmapModel m;
  m.cameras[1] = {1, "PINHOLE", 40, 30, {35.5, 36.25, 20.0, 15.0}};
  m.cameras[3] = {3, "SIMPLE_PINHOLE", 40, 30, {33.0, 19.5, 14.5}};
  for (int i = 0; i < 3; ++i) {
    ColmapImage im;
    im.id = 10 + i;
    im.qvec = Eigen::Vector4d(0.9, 0.1 * i, -0.2, 0.3).normalized();
    im.tvec = Eigen::Vector3d(0.1 * i, -0.5, 2.0 + i);
    im.camera_id = i == 2 ? 3 : 1;
    im.name = i == 1 ? "sub/dir/b.png" : (i == 0 ? "a.png" : "c.png");
    if (i != 2) {  // image 12 has no keypoints
      im.xys = {{1.25, 2.5}, {3.0, 4.75}};
      im.point3d_ids = {1, -1};
    }
    m.images.push_back(im);
  }
  ColmapPoint p;
  p.id = 1;
  p.xyz = {0.1, -0.2, 3.3};
  p.rgb[0] = 10;
  p.rgb[1] = 200;
  p.rgb[2] = 255;
  p.error = 0.75;
  p.track = {{10, 0}, {11, 0}};
  m.points.push_back(p);
  return m;
}

void expect_same(const ColmapModel& a, const ColmapModel& b) {
  ASSERT_EQ(a.cameras.size(), b.cameras.size());
  for (auto& [id, c] : a.cameras) {
    const auto& d = b.cameras.at(id);
    EXPECT_EQ(c.model, d.model);
    EXPECT_EQ(c.width, d.width);
    EXPECT_EQ(c.height, d.height);
    EXPECT_EQ(c.params, d.params);
  }
  ASSERT_EQ(a.images.size(), b.images.size());
  for (size_t i = 0; i < a.images.size(); ++i) {
    EXPECT_EQ(a.images[i].id, b.images[i].id);
    EXPECT_EQ(a.images[i].name, b.images[i].name);
    EXPECT_EQ(a.images[i].camera_id, b.images[i].camera_id);
    EXPECT_EQ(a.images[i].qvec, b.images[i].qvec);
    EXPECT_EQ(a.images[i].tvec, b.images[i].tvec);
    EXPECT_EQ(a.images[i].xys, b.images[i].xys);
    EXPECT_EQ(a.images[i].point3d_ids, b.images[i].point3d_ids);
  }
  ASSERT_EQ(a.points.size(), b.points.size());
  for (size_t i = 0; i < a.points.size(); ++i) {
    EXPECT_EQ(a.points[i].id, b.points[i].id);
    EXPECT_EQ(a.points[i].xyz, b.points[i].xyz);
    EXPECT_EQ(a.points[i].rgb[0], b.points[i].rgb[0]);
    EXPECT_EQ(a.points[i].rgb[2], b.points[i].rgb[2]);
    EXPECT_EQ(a.points[i].error, b.points[i].error);
    EXPECT_EQ(a.points[i].track, b.points[i].track);
  }
}

// A complete little scene folder for loader tests.
void write_scene(const fs::path& root, const ColmapModel& m) {
  write_colmap_bin(root / "sparse" / "0", m);
  for (auto& im : m.images) save_png(root / "images" / im.name, Image(40, 30, 3, 0.5f));
}

}  // namespace

TEST(Colmap, BinaryRoundTripIsExact) {
  test::TempDir tmp;
  ColmapModel m = sample_model();
  write_colmap_bin(tmp.path, m);
  expect_same(m, read_colmap_bin(tmp.path));
}

TEST(Colmap, TextAndBinaryLoadIdentically) {
  test::TempDir tmp;
  ColmapModel m = sample_model();
  write_colmap_bin(tmp / "bin", m);
  write_colmap_txt(tmp / "txt", m);
  expect_same(read_colmap(tmp / "bin"), read_colmap(tmp / "txt"));
  // and as whole scenes
  write_scene(tmp / "s1", m);
  write_scene(tmp / "s2", m);
  fs::remove_all(tmp / "s2" / "sparse" / "0");
  write_colmap_txt(tmp / "s2" / "sparse" / "0", m);
  Scene a = load_scene(tmp / "s1"), b = load_scene(tmp / "s2");
  ASSERT_EQ(a.views.size(), b.views.size());
  for (size_t i = 0; i < a.views.size(); ++i) {
    EXPECT_EQ(a.views[i].name, b.views[i].name);
    EXPECT_EQ(a.views[i].R, b.views[i].R);
    EXPECT_EQ(a.views[i].fx, b.views[i].fx);
  }
}

TEST(Colmap, RealModelsBinAndTxtAgree) {
  HGS_REQUIRE_SHARED(kumamon, "kumamon");
  test::TempDir tmp;
  ColmapModel m = read_colmap(kumamon / "sparse" / "0");
  EXPECT_EQ(m.images.size(), 84u);
  EXPECT_EQ(m.points.size(), 11947u);
  write_colmap_txt(tmp.path, m);
  expect_same(m, read_colmap_txt(tmp.path));
}

TEST(Scene, SplitNamesAndSubfolders) {
  test::TempDir tmp;
  write_scene(tmp.path, sample_model());
  Scene s = load_scene(tmp.path);
  ASSERT_EQ(s.views.size(), 3u);
  EXPECT_EQ(s.views[0].name, "a.png");
  EXPECT_EQ(s.views[2].name, "sub/dir/b.png");  // sorted by name
  EXPECT_EQ(s.views[2].stem, "sub/dir/b");
  EXPECT_TRUE(s.views[0].is_test);  // every 8th view, starting with the first
  EXPECT_FALSE(s.views[1].is_test);
  EXPECT_EQ(s.views[1].fx, 33.0);  // SIMPLE_PINHOLE
  atomic_write_text(tmp / "test.txt", "c.png\nsub/dir/b.png\n");
  Scene t = load_scene(tmp.path);
  EXPECT_EQ(t.test_indices(), (std::vector<int>{1, 2}));
  EXPECT_EQ(t.split_source, "test.txt");
}

TEST(Scene, DownscaleDividesIntrinsicsAndAveragesPixels) {
  test::TempDir tmp;
  write_scene(tmp.path, sample_model());
  Scene s = load_scene(tmp.path, {2, false});
  EXPECT_EQ(s.views[0].width, 20);
  EXPECT_EQ(s.views[0].height, 15);
  EXPECT_DOUBLE_EQ(s.views[0].fx, 35.5 / 2);
  EXPECT_DOUBLE_EQ(s.views[0].cx, 10.0);
  Image im = s.load_image(0);
  EXPECT_EQ(im.width, 20);
  EXPECT_FALSE(fs::exists(tmp / "images_2"));
  Scene c = load_scene(tmp.path, {2, true});
  EXPECT_TRUE(fs::exists(tmp / "images_2" / "sub" / "dir" / "b.png"));
  EXPECT_EQ(c.load_image(2).width, 20);
}

TEST(Scene, MasksFeaturesAndConfidence) {
  test::TempDir tmp;
  write_scene(tmp.path, sample_model());
  LabelMap m(40, 30);
  m.at(5, 5) = 3;
  save_label_png(tmp / "masks" / "a.png", m);
  std::vector<float> feat(3 * 4 * 2);
  for (size_t i = 0; i < feat.size(); ++i) feat[i] = float(i);
  write_npy(tmp / "features" / "a.npy", make_npy_f32({3, 4, 2}, feat.data()));
  atomic_write_text(tmp / "masks" / "objects.json", R"({"3": "red mug"})");
  Scene s = load_scene(tmp.path);
  EXPECT_TRUE(s.has_masks());
  EXPECT_EQ(s.num_objects(), 3);
  EXPECT_EQ(s.object_names.at(3), "red mug");
  int dim = 0;
  auto f = s.load_features(0, dim);
  ASSERT_TRUE(f.has_value());
  EXPECT_EQ(dim, 2);
  EXPECT_EQ(f->size(), 40u * 30 * 2);
  EXPECT_FLOAT_EQ((*f)[0], 0.f);  // corner pixel maps onto the corner patch (clamped)
  EXPECT_FALSE(s.load_features(1, dim).has_value());
}

TEST(Scene, UpsampleBilinearMatchesHandComputation) {
  // 1x2 grid upsampled to 1x4: pixel centres at 0.25, 0.75, 1.25, 1.75 of the source -> clamp, blend.
  float src[2] = {0.f, 4.f};
  auto out = upsample_bilinear(src, 1, 2, 1, 1, 4);
  EXPECT_FLOAT_EQ(out[0], 0.f);
  EXPECT_FLOAT_EQ(out[1], 1.f);
  EXPECT_FLOAT_EQ(out[2], 3.f);
  EXPECT_FLOAT_EQ(out[3], 4.f);
}

TEST(Scene, BadInputsGiveOneLineErrors) {
  test::TempDir tmp;
  EXPECT_NE(test::error_of([&] { load_scene(tmp / "missing"); }).find("scene folder not found"), std::string::npos);
  write_scene(tmp / "s", sample_model());
  // image listed but missing
  fs::remove(tmp / "s" / "images" / "c.png");
  std::string e = test::error_of([&] { load_scene(tmp / "s"); });
  EXPECT_NE(e.find("c.png"), std::string::npos) << e;
  EXPECT_NE(e.find("missing"), std::string::npos) << e;
  // truncated .bin
  write_scene(tmp / "t", sample_model());
  auto bytes = read_file_bytes(tmp / "t" / "sparse" / "0" / "images.bin");
  bytes.resize(bytes.size() - 9);
  atomic_write_bytes(tmp / "t" / "sparse" / "0" / "images.bin", bytes.data(), bytes.size());
  e = test::error_of([&] { load_scene(tmp / "t"); });
  EXPECT_NE(e.find("images.bin: truncated file"), std::string::npos) << e;
  // unknown (non-pinhole) camera model
  ColmapModel m = sample_model();
  m.cameras[1] = {1, "OPENCV", 40, 30, {35, 35, 20, 15, 0.1, 0.01, 0, 0}};
  write_scene(tmp / "u", m);
  e = test::error_of([&] { load_scene(tmp / "u"); });
  EXPECT_NE(e.find("OPENCV"), std::string::npos) << e;
  EXPECT_NE(e.find("colmap image_undistorter"), std::string::npos) << e;
  // corrupt count in cameras.bin
  write_scene(tmp / "v", sample_model());
  uint64_t huge = 1ull << 40;
  auto cb = read_file_bytes(tmp / "v" / "sparse" / "0" / "cameras.bin");
  std::memcpy(cb.data(), &huge, 8);
  atomic_write_bytes(tmp / "v" / "sparse" / "0" / "cameras.bin", cb.data(), cb.size());
  e = test::error_of([&] { load_scene(tmp / "v"); });
  EXPECT_NE(e.find("cameras.bin: corrupt file"), std::string::npos) << e;
}

TEST(Scene, RealScenesLoad) {
  HGS_REQUIRE_SHARED(kumamon, "kumamon");
  Scene s = load_scene(kumamon, {4, false});
  EXPECT_EQ(s.views.size(), 84u);
  EXPECT_EQ(s.test_indices().size(), 11u);
  EXPECT_EQ(s.views[0].width, 1258 / 4);
  Image im = s.load_image(0);
  EXPECT_EQ(im.width, 1258 / 4);
  EXPECT_EQ(im.height, 707 / 4);
  auto lab = test::shared_data("lab_room");
  if (!lab.empty()) {
    Scene r = load_scene(lab);
    EXPECT_EQ(r.views.size(), 128u);
    EXPECT_EQ(r.points.size(), 5751u);
  }
}

TEST(Cli, InfoOnRealData) {
  HGS_REQUIRE_SHARED(kumamon, "kumamon");
  auto r = test::run_hgs("info " + kumamon.string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("views        84"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("problems     none"), std::string::npos) << r.out;
}

TEST(Cli, InfoSaysWhereTheGroundTruthsNamesComeFrom) {
  test::TempDir tmp;
  const fs::path s = tmp / "s";
  auto g = test::run_hgs("synth --world simple --out " + s.string() +
                         " --views 6 --width 48 --height 32 --points 200 --feature-dim 8 --quiet");
  ASSERT_EQ(g.exit_code, 0) << g.err;
  auto r = test::run_hgs("info " + s.string());
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("ground truth gt/instances/ (6 maps), names from gt/objects.json"), std::string::npos) << r.out;
  fs::remove(s / "gt" / "objects.json");  // a real capture's layout: the masks' objects.json names gt/instances
  r = test::run_hgs("info " + s.string());
  EXPECT_NE(r.out.find("ground truth gt/instances/ (6 maps), names from masks/objects.json"), std::string::npos)
      << r.out;
  EXPECT_EQ(r.out.find("synthetic"), std::string::npos) << r.out;
}

TEST(Cli, InfoOnBadSceneFailsCleanly) {
  test::TempDir tmp;
  auto r = test::run_hgs("info " + (tmp / "nope").string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("hgs: error: "), std::string::npos);
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
}

TEST(Cli, HelpForEverySubcommand) {
  auto r = test::run_hgs("--help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* sub : {"synth", "info"}) {
    EXPECT_NE(r.out.find(sub), std::string::npos);
    auto s = test::run_hgs(std::string(sub) + " --help");
    EXPECT_EQ(s.exit_code, 0) << sub;
    EXPECT_NE(s.out.find("Usage"), std::string::npos) << sub;
  }
}
