// `hgs masks generate` and `hgs masks click` end to end on a tiny synthetic scene with the tiny SAM: the files
// match the library's output, a second run resumes (skips views done), the JSON imports, bad input fails cleanly.
#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "core/image.h"
#include "masks/rle.h"
#include "nn/openblas_env.h"
#include "sam/amg.h"
#include "sam_test_util.h"
#include "scene/scene.h"
#include "test_util.h"

// The test process runs OpenBLAS with the kernels hgs picks for itself (nn/openblas_env.h), so that the library's
// products here and the hgs processes' products agree to the bit: on a CPU whose model OpenBLAS does not know (seen:
// an Emerald Rapids guest) the library alone falls back to its SSE3 kernels, whose sums round differently.
HGS_OPENBLAS_PREINIT();

namespace hgs::test {
namespace {
namespace fs = std::filesystem;

// Thresholds for random weights (their masks are speckled, their IoU predictions low).
const std::string kAmgArgs =
    " --points-per-side 4 --points-per-batch 5 --pred-iou-thresh 0 --stability-thresh 0"
    " --stability-offset 0.05 --box-nms-thresh 0.9";

fs::path make_scene(const TempDir& t) {
  const fs::path s = t / "scene";
  auto r = run_hgs("synth --world simple --out " + s.string() +
                   " --views 3 --width 56 --height 40 --points 400 --feature-dim 4 --quiet");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return s;
}

TEST(SamCli, GenerateWritesSamJsonMatchingTheLibraryAndResumes) {
  TempDir t;
  const fs::path s = make_scene(t), out = t / "sam";
  const std::string w = sam_data("tiny_sam.safetensors").string();
  auto r = run_hgs("masks generate " + s.string() + " --sam " + w + " --out " + out.string() + kAmgArgs + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("wrote 3 SAM mask files"), std::string::npos) << r.out;

  // View 0 against the library.
  Scene sc = load_scene(s);
  Image img = sc.load_image(0);
  sam::AmgOptions o;
  o.points_per_side = 4;
  o.points_per_batch = 5;
  o.pred_iou_thresh = 0.f;
  o.stability_score_thresh = 0.f;
  o.stability_score_offset = 0.05f;
  o.box_nms_thresh = 0.9f;
  std::vector<sam::AmgMask> ms = sam::generate_masks(tiny_sam(), tiny_sam().embed(img), o);
  ASSERT_FALSE(ms.empty());
  nlohmann::json j = nlohmann::json::parse(std::ifstream(out / (sc.views[0].stem + ".json")));
  ASSERT_EQ(j.size(), ms.size());
  for (size_t k = 0; k < ms.size(); ++k) {
    masks::Rle rle;
    rle.height = j[k]["segmentation"]["size"][0];
    rle.width = j[k]["segmentation"]["size"][1];
    EXPECT_EQ(rle.height, img.height);
    EXPECT_EQ(rle.width, img.width);
    rle.counts = masks::rle_counts_from_string(j[k]["segmentation"]["counts"], "test");
    EXPECT_EQ(masks::rle_decode(rle, "test"), ms[k].mask) << k;
    EXPECT_EQ(j[k]["area"].get<int>(), ms[k].area);
    EXPECT_FLOAT_EQ(j[k]["predicted_iou"].get<float>(), ms[k].predicted_iou);
  }

  // Resume: nothing left to do; a removed file is recomputed.
  fs::remove(out / (sc.views[1].stem + ".json"));
  r = run_hgs("masks generate " + s.string() + " --sam " + w + " --out " + out.string() + kAmgArgs + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("wrote 1 SAM mask files"), std::string::npos) << r.out;
  EXPECT_NE(r.out.find("2 skipped"), std::string::npos) << r.out;
  EXPECT_TRUE(fs::exists(out / (sc.views[1].stem + ".json")));

  // The form `hgs masks import --from sam-json` reads.
  r = run_hgs("masks import " + s.string() + " --from sam-json " + out.string() + " --force --quiet");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("imported 3 of 3 views"), std::string::npos) << r.out;
}

TEST(SamCli, GenerateInBf16SaysSoAndWritesMasks) {
  TempDir t;
  const fs::path s = make_scene(t), out = t / "sam";
  const std::string w = sam_data("tiny_sam.safetensors").string();
  auto r = run_hgs("masks generate " + s.string() + " --sam " + w + " --out " + out.string() + kAmgArgs +
                   " --precision bf16");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("bf16 products"), std::string::npos) << r.err;
  EXPECT_NE(r.out.find("wrote 3 SAM mask files"), std::string::npos) << r.out;
  // The masks of view 0 against the library's float32 masks: the same count (the thresholds are 0) and each
  // mask nearly the same pixels.
  Scene sc = load_scene(s);
  Image img = sc.load_image(0);
  sam::AmgOptions o;
  o.points_per_side = 4, o.points_per_batch = 5, o.pred_iou_thresh = 0.f, o.stability_score_thresh = 0.f;
  o.stability_score_offset = 0.05f, o.box_nms_thresh = 0.9f;
  std::vector<sam::AmgMask> ms = sam::generate_masks(tiny_sam(), tiny_sam().embed(img), o);
  nlohmann::json j = nlohmann::json::parse(std::ifstream(out / (sc.views[0].stem + ".json")));
  ASSERT_FALSE(ms.empty());
  EXPECT_EQ(j.size(), ms.size());
  size_t differ = 0, total = 0;
  for (size_t k = 0; k < std::min(ms.size(), j.size()); ++k) {
    masks::Rle rle;
    rle.height = j[k]["segmentation"]["size"][0];
    rle.width = j[k]["segmentation"]["size"][1];
    rle.counts = masks::rle_counts_from_string(j[k]["segmentation"]["counts"], "test");
    const std::vector<uint8_t> m16 = masks::rle_decode(rle, "test");
    for (size_t i = 0; i < m16.size(); ++i) differ += m16[i] != ms[k].mask[i];
    total += m16.size();
  }
  EXPECT_LT(double(differ) / double(total), 0.02) << differ << " of " << total;
  r = run_hgs("masks click " + s.string() + " --sam " + w + " --view 0 --point 3,4 --precision f16");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("--precision"), std::string::npos) << r.err;
}

TEST(SamCli, ClickWritesTheBestMultimaskOutput) {
  TempDir t;
  const fs::path s = make_scene(t);
  const std::string w = sam_data("tiny_sam.safetensors").string();
  auto r =
      run_hgs("masks click " + s.string() + " --sam " + w + " --view 2 --point 30,20 --out " + (t / "m.png").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  Scene sc = load_scene(s);
  Image img = sc.load_image(2);
  sam::ImageEmbedding e = tiny_sam().embed(img);
  sam::Prompt p;
  p.points = {{30.f, 20.f}};
  p.labels = {1};
  sam::Prediction pr = tiny_sam().predict(e, p);
  int best = 1;
  for (int k = 2; k < 4; ++k)
    if (pr.iou[k] > pr.iou[best]) best = k;
  std::vector<float> full = tiny_sam().upscale_masks(e, pr.lowres.data() + size_t(best) * pr.size * pr.size, 1);
  LabelMap png = load_label_png(t / "m.png");
  ASSERT_EQ(png.width, img.width);
  ASSERT_EQ(png.height, img.height);
  size_t inside = 0;
  for (size_t i = 0; i < full.size(); ++i) {
    EXPECT_EQ(png.v[i], full[i] > 0.f ? 255 : 0) << i;
    inside += png.v[i] > 0;
  }
  EXPECT_GT(inside, 0u);
}

TEST(SamCli, BadInputIsOneLineError) {
  TempDir t;
  const fs::path s = make_scene(t);
  const std::string w = sam_data("tiny_sam.safetensors").string();
  auto r = run_hgs("masks click " + s.string() + " --sam " + w + " --view 7 --point 3,4");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("--view 7"), std::string::npos) << r.err;
  r = run_hgs("masks click " + s.string() + " --sam " + w + " --view 0 --point 3:4");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("--point"), std::string::npos) << r.err;
  r = run_hgs("masks click " + s.string() + " --sam " + w + " --view 0 --point 3,4 --vit-heads 5");  // not the tables'
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("5 heads given"), std::string::npos) << r.err;
  std::ofstream(t / "bad.safetensors") << "not a model";
  r = run_hgs("masks generate " + s.string() + " --sam " + (t / "bad.safetensors").string() + " --quiet");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("bad.safetensors"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(s / "sam"));
  r = run_hgs("masks generate --help");
  EXPECT_EQ(r.exit_code, 0);
  EXPECT_NE(r.out.find("--points-per-side"), std::string::npos);
}

}  // namespace
}  // namespace hgs::test
