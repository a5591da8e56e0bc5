// `hgs prepare` end to end with Debian's colmap: a subset of the real goldcape photos posed and compared with the
// shared COLMAP model after a similarity alignment, the whole chain with the tiny SAM / CLIP weights of tests/data
// ending in `hgs train` and `hgs query`, and each kind of bad input. Skips without ../shared or colmap.
#include <gtest/gtest.h>

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>

#include "core/image.h"
#include "prepare/run_tool.h"
#include "scene/colmap.h"
#include "test_util.h"

namespace hgs::test {
namespace {
namespace fs = std::filesystem;

const char* kColmapSkip = "colmap is not installed (scripts/setup installs Debian's colmap): skipping";

nlohmann::json read_json(const fs::path& p) { return nlohmann::json::parse(std::ifstream(p)); }

// The first `n` goldcape photos (by name) as symlinks in `dir`.
void goldcape_photos(const fs::path& gc, const fs::path& dir, int n, int skip = 0) {
  fs::create_directories(dir);
  std::vector<fs::path> all;
  for (const auto& e : fs::directory_iterator(gc / "images")) all.push_back(e.path());
  std::sort(all.begin(), all.end());
  for (int i = skip; i < skip + n && i < int(all.size()); ++i)
    if (!fs::exists(dir / all[i].filename())) fs::create_symlink(all[i], dir / all[i].filename());
}

// Camera centres and camera-to-world rotations by image name.
struct Poses {
  std::map<std::string, Eigen::Vector3d> centre;
  std::map<std::string, Eigen::Matrix3d> c2w;
};
Poses poses_of(const fs::path& sparse) {
  Poses p;
  for (const ColmapImage& im : read_colmap(sparse).images) {
    const Eigen::Matrix3d R = qvec_to_rotmat(im.qvec);
    p.centre[im.name] = -R.transpose() * im.tvec;
    p.c2w[im.name] = R.transpose();
  }
  return p;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0.0 : v[v.size() / 2];
}

// The goldcape subset posed by `hgs prepare`: 16 photos, --max-size 512 and 2048 features for CI time. Each test
// makes its own (ctest runs every test case in its own process).
RunResult prepare_subset(const fs::path& gc, const TempDir& t, const std::string& extra = "") {
  goldcape_photos(gc, t / "photos", 16);
  return run_hgs("prepare " + (t / "photos").string() + " --out " + (t / "scene").string() +
                 " --max-size 512 --max-features 2048 --quiet" + extra);
}

#define REQUIRE_COLMAP() \
  if (!prepare::find_program("colmap")) GTEST_SKIP() << kColmapSkip

TEST(PrepareGoldcape, PosesAgreeWithTheSharedModelAndTrainingAsksForMasks) {
  HGS_REQUIRE_SHARED(gc, "goldcape");
  REQUIRE_COLMAP();
  TempDir tmp;
  const fs::path scene = tmp / "scene";
  RunResult first = prepare_subset(gc, tmp);
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const nlohmann::json j = read_json(scene / "prepare.json");
  const nlohmann::json& p = j["poses"];
  const int images = p["images"], registered = p["registered"];
  EXPECT_EQ(images, 16);
  EXPECT_GE(registered, int(std::ceil(0.9 * images))) << p.dump();
  EXPECT_LE(p["mean_reprojection_error_px"].get<double>(), 1.0);
  EXPECT_EQ(p["cameras"], 1);
  EXPECT_EQ(j["input"]["resized"], 16);  // 912 px -> 512 px

  // The scene `hgs train` reads: PINHOLE cameras, images of the model's size.
  ColmapModel m = read_colmap(scene / "sparse" / "0");
  for (auto& [id, cam] : m.cameras) EXPECT_EQ(cam.model, "PINHOLE");
  int w = 0, h = 0;
  image_size(scene / "images" / m.images[0].name, w, h);
  EXPECT_EQ(uint64_t(w), m.cameras.begin()->second.width);

  // Camera centres against the shared model (same photos) after a similarity alignment (Umeyama).
  Poses est = poses_of(scene / "sparse" / "0"), ref = poses_of(gc / "sparse" / "0");
  std::vector<std::string> names;
  for (auto& [n, c] : est.centre)
    if (ref.centre.count(n)) names.push_back(n);
  ASSERT_GE(names.size(), 14u);
  Eigen::MatrixXd src(3, names.size()), dst(3, names.size());  // dynamic: GCC 12 warns inside umeyama on 3xN
  for (size_t i = 0; i < names.size(); ++i) src.col(i) = est.centre[names[i]], dst.col(i) = ref.centre[names[i]];
  const Eigen::MatrixXd T = Eigen::umeyama(src, dst, true);
  const Eigen::Matrix3d sR = T.topLeftCorner(3, 3);
  const Eigen::Matrix3d R = sR / std::cbrt(sR.determinant());
  double size = 0;  // scene size: the largest distance between two reference centres of these views
  for (size_t i = 0; i < names.size(); ++i)
    for (size_t k = i + 1; k < names.size(); ++k) size = std::max(size, (dst.col(i) - dst.col(k)).norm());
  std::vector<double> pos, rot;
  for (size_t i = 0; i < names.size(); ++i) {
    const Eigen::Vector3d c = sR * src.col(i) + T.topRightCorner(3, 1);
    pos.push_back((c - dst.col(i)).norm() / size);
    const Eigen::Matrix3d d = ref.c2w[names[i]].transpose() * R * est.c2w[names[i]];
    rot.push_back(std::acos(std::clamp((d.trace() - 1) / 2, -1.0, 1.0)) * 180 / M_PI);
  }
  const double med_pos = median(pos), med_rot = median(rot);
  std::printf(
      "goldcape subset: %d of %d registered, reprojection %.3f px, median centre error %.4f of the scene "
      "size (%.3f), median rotation error %.3f deg\n",
      registered, images, p["mean_reprojection_error_px"].get<double>(), med_pos, size, med_rot);
  EXPECT_LT(med_pos, 0.01);  // about 0.0010 on goldcape
  EXPECT_LT(med_rot, 1.0);   // measured 0.245 deg

  // Training the prepared scene (no --sam) as hybrid says how to get masks.
  RunResult r = run_hgs("train " + scene.string() + " --iters 2 --out " + (tmp / "nomask").string() + " --quiet");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_NE(r.err.find("--sam"), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("--method rgb"), std::string::npos) << r.err;
}

// The whole chain with the tiny weights of tests/data, then training and a query (plumbing, not accuracy): poses
// first, then a rerun that adds --sam and --clip keeps them and runs only the mask and language stages.
TEST(PrepareGoldcape, ChainWithTinyWeightsEndsInTrainAndQuery) {
  HGS_REQUIRE_SHARED(gc, "goldcape");
  REQUIRE_COLMAP();
  TempDir tmp;
  const fs::path scene = tmp / "scene";
  RunResult first = prepare_subset(gc, tmp, " --until poses");
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const std::string sam = (fs::path(HGS_TEST_DATA) / "sam" / "tiny_sam.safetensors").string();
  const std::string clip = (fs::path(HGS_TEST_DATA) / "clip" / "hf_f32" / "model.safetensors").string();
  RunResult r =
      prepare_subset(gc, tmp,
                     " --sam " + sam + " --clip " + clip +
                         " --points-per-side 8 --pred-iou-thresh 0 --stability-thresh 0 --stability-offset 0.05"
                         " --box-nms-thresh 0.9 --depth-iters 30 --min-views 2 --input-size 64 --text 'gold cape'");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = read_json(scene / "prepare.json");
  for (const auto& st : j["stages"]) {
    const std::string name = st["stage"];
    const bool pose = name == "features" || name == "matching" || name == "mapping" || name == "undistort";
    if (pose) {
      EXPECT_TRUE(st["reused"].get<bool>()) << name << " ran again";
    }
  }
  EXPECT_GT(j["masks"]["masks_per_view"]["mean"].get<double>(), 0.0) << j.dump();
  EXPECT_GT(j["masks"]["objects"].get<int>(), 0) << j.dump();
  const nlohmann::json te = read_json(scene / "text_embeddings.json");
  EXPECT_TRUE(te.contains("gold cape"));
  EXPECT_TRUE(te.contains("object"));
  ColmapModel m = read_colmap(scene / "sparse" / "0");
  for (const ColmapImage& im : m.images) {
    const std::string stem = fs::path(im.name).replace_extension().string();
    EXPECT_TRUE(fs::exists(scene / "masks" / (stem + ".png"))) << stem;
    EXPECT_TRUE(fs::exists(scene / "features" / (stem + ".npy"))) << stem;
  }
  const fs::path model = tmp / "model";
  // 200 steps: the object table is first fused at step 100 (hybrid --fusion-every).
  r = run_hgs("train " + scene.string() + " --iters 200 --downscale 2 --out " + model.string() + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  // Pixel mode: the tiny random SAM's few masks may leave no Gaussian with a foreground id after 200 steps (then
  // object mode says "no foreground objects"), while the language map is rendered whatever the objects.
  r = run_hgs("query " + scene.string() + " " + model.string() +
              " --downscale 2 --text 'gold cape' --mode pixel --split all --quiet --out " + (tmp / "q").string());
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json q = read_json(tmp / "q" / "result.json");
  EXPECT_FALSE(q.empty()) << q.dump();
  EXPECT_EQ(std::distance(fs::directory_iterator(tmp / "q"), fs::directory_iterator{}), long(1 + m.images.size()))
      << "a folder per view and result.json";
}

}  // namespace
}  // namespace hgs::test
