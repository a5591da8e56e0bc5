// `hgs embed-text` and `hgs features` end to end on the tiny reference model: outputs equal the library's,
// errors are one line with no partial output.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "clip/model.h"
#include "clip_test_util.h"
#include "core/fs.h"
#include "core/half.h"
#include "core/image.h"
#include "core/npy.h"
#include "nn/safetensors.h"
#include "scene/colmap.h"
#include "test_util.h"

using namespace hgs;
namespace fs = std::filesystem;

namespace {

const std::string kModel = hgs::test::clip_data("hf_f32/model.safetensors").string();

// A two-view scene: images/a.png (64 x 40) and images/sub/b.png, one PINHOLE camera.
void make_scene(const fs::path& root) {
  ColmapModel m;
  m.cameras[1] = {1, "PINHOLE", 64, 40, {50, 50, 32, 20}};
  for (int i = 0; i < 2; ++i) {
    ColmapImage im;
    im.id = i + 1;
    im.camera_id = 1;
    im.name = i == 0 ? "a.png" : "sub/b.png";
    im.tvec = {0.1 * i, 0, 0};
    m.images.push_back(im);
    Image img(64, 40, 3);
    for (size_t k = 0; k < img.px.size(); ++k) img.px[k] = float((k * (31 + i * 17)) % 251) / 250.f;
    fs::create_directories((root / "images" / im.name).parent_path());
    save_png(root / "images" / im.name, img);
  }
  ColmapPoint p;
  p.id = 1;
  m.points.push_back(p);
  fs::create_directories(root / "sparse" / "0");
  write_colmap_txt(root / "sparse" / "0", m);
}

}  // namespace

TEST(ClipCli, EmbedTextMatchesLibrary) {
  test::TempDir t;
  auto out = t / "text_embeddings.json";
  auto r = test::run_hgs("embed-text --clip " + kModel + " --text 'a photo of a cat' --text chair --canonical --out " +
                         out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto j = nlohmann::json::parse(read_file_text(out));
  ASSERT_EQ(j.size(), 6u);
  auto m = clip::ClipModel::load(kModel);
  // Same batch as the command (products of different batch sizes may differ in the last bit).
  auto e = m.embed_text({"a photo of a cat", "chair", "object", "things", "stuff", "texture"});
  EXPECT_EQ(j["a photo of a cat"].get<std::vector<float>>(), std::vector<float>(e.begin(), e.begin() + 32));
  EXPECT_EQ(j["texture"].get<std::vector<float>>(), std::vector<float>(e.begin() + 5 * 32, e.end()));
  // --merge keeps existing phrases.
  r = test::run_hgs("embed-text --clip " + kModel + " --text mug --merge --out " + out.string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(nlohmann::json::parse(read_file_text(out)).size(), 7u);
}

TEST(ClipCli, EmbedTextErrors) {
  test::TempDir t;
  std::vector<float> v(4, 0.f);
  nn::write_safetensors(t / "x.safetensors", {{"foo", {4}, v.data()}});
  auto out = t / "o.json";
  auto r = test::run_hgs("embed-text --clip " + (t / "x.safetensors").string() + " --text cat --out " + out.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("hgs: error:"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("not a CLIP model"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  r = test::run_hgs("embed-text --clip " + kModel + " --out " + out.string());
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no phrases"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(out));
  EXPECT_EQ(test::run_hgs("embed-text --help").exit_code, 0);
  EXPECT_EQ(test::run_hgs("features --help").exit_code, 0);
}

TEST(ClipCli, FeaturesWritesF16Grids) {
  test::TempDir t;
  make_scene(t.path);
  auto r = test::run_hgs("features " + t.path.string() + " --clip " + kModel + " --input-size 32");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  auto m = clip::ClipModel::load(kModel);
  clip::DenseOptions o;
  o.input_size = 32;
  for (const char* stem : {"a", "sub/b"}) {
    NpyArray a = read_npy(t.path / "features" / (std::string(stem) + ".npy"));
    EXPECT_EQ(a.dtype, DType::F16);
    // 64 x 40 at shorter side 32: grid round(40 * 0.8 / 16) = 2 x round(64 * 0.8 / 16) = 3
    ASSERT_EQ(a.shape, (std::vector<size_t>{2, 3, 32}));
    Image img = load_image(t.path / "images" / (std::string(stem) + ".png"));
    auto f = m.dense_features(img, o);
    auto got = a.to_float();
    for (size_t i = 0; i < got.size(); ++i) EXPECT_EQ(got[i], half_to_float(float_to_half(f.data[i])));
  }
  // --precision bf16 (its error is bounded in ClipModel.Bf16DenseFeaturesWithinBoundOfFloat32): the command
  // takes it and says so; a precision it does not know is refused.
  r = test::run_hgs("features " + t.path.string() + " --clip " + kModel + " --input-size 96 --precision bf16");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("bf16"), std::string::npos) << r.err;
  EXPECT_EQ(read_npy(t.path / "features" / "a.npy").shape[2], 32u);
  r = test::run_hgs("features " + t.path.string() + " --clip " + kModel + " --precision int8");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("--precision"), std::string::npos) << r.err;
  // A missing scene is a one-line error.
  r = test::run_hgs("features " + (t / "nope").string() + " --clip " + kModel);
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("scene folder not found"), std::string::npos) << r.err;
}
