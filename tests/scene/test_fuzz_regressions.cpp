// Inputs found by fuzzing the scene loaders (fuzz/fuzz_colmap_{bin,txt}.cpp, fuzz_objects_json.cpp,
// fuzz_text_embeddings_json.cpp; docs/reliability.md), each failing before its fix: they now give a one-line
// hgs::Error naming the file.
#include <gtest/gtest.h>

#include <limits>
#include <string>

#include "core/error.h"
#include "core/fs.h"
#include "expect_error.h"
#include "scene/colmap.h"
#include "scene/scene.h"
#include "test_util.h"

using namespace hgs;
namespace fs = std::filesystem;

namespace {
// A one-camera, one-image model (COLMAP text) with images/<name> present when it can be.
fs::path scene_with(const fs::path& root, const ColmapCamera& cam, const std::string& name) {
  ColmapModel m;
  m.cameras[cam.id] = cam;
  ColmapImage im;
  im.id = 1;
  im.camera_id = cam.id;
  im.name = name;
  im.tvec = {0, 0, 2};
  m.images.push_back(im);
  ColmapPoint p;
  p.id = 1;
  m.points.push_back(p);
  write_colmap_txt(root / "sparse" / "0", m);
  ensure_dir(root / "images");
  if (name.size() < 200) atomic_write_text(root / "images" / name, "");
  return root;
}
const ColmapCamera kCam{1, "PINHOLE", 32, 24, {30, 30, 16, 12}};
}  // namespace

// fuzz_colmap_txt: an image name longer than the system's file-name limit threw std::filesystem_error from
// fs::exists in load_scene.
TEST(FuzzRegressions, SceneImageNameTooLong) {
  test::TempDir tmp;
  const std::string name(300, 'a');
  scene_with(tmp.path, kCam, name);
  EXPECT_FILE_ERROR(load_scene(tmp.path), tmp / "images" / name, "cannot access");
}

// Camera sizes from the file sized every view (and its render buffers) unchecked: 0, or 2^40 pixels a side.
TEST(FuzzRegressions, SceneCameraSizeOutOfRange) {
  for (uint64_t w : {uint64_t(0), uint64_t(1) << 40}) {
    test::TempDir tmp;
    ColmapCamera c = kCam;
    c.width = w;
    scene_with(tmp.path, c, "a.png");
    EXPECT_FILE_ERROR(load_scene(tmp.path), tmp / "sparse" / "0" / "cameras", "expected 1..65536");
  }
}

TEST(FuzzRegressions, SceneNonFiniteIntrinsicsAndPose) {
  {
    test::TempDir tmp;
    ColmapCamera c = kCam;
    scene_with(tmp.path, c, "a.png");
    // NaN written as text does not parse back ("nan"); the binary model holds it as COLMAP would.
    ColmapModel m = read_colmap(tmp / "sparse" / "0");
    m.cameras.at(c.id).params[0] = std::numeric_limits<double>::quiet_NaN();
    for (const char* f : {"cameras.txt", "images.txt", "points3D.txt"}) fs::remove(tmp / "sparse" / "0" / f);
    write_colmap_bin(tmp / "sparse" / "0", m);
    EXPECT_FILE_ERROR(load_scene(tmp.path), tmp / "sparse" / "0" / "cameras", "invalid intrinsics");
  }
  {
    test::TempDir tmp;
    scene_with(tmp.path, kCam, "a.png");
    ColmapModel m = read_colmap(tmp / "sparse" / "0");
    m.images[0].qvec = {0, 0, 0, 0};
    write_colmap_txt(tmp / "sparse" / "0", m);
    EXPECT_FILE_ERROR(load_scene(tmp.path), tmp / "sparse" / "0" / "images", "invalid pose");
  }
}

// An image name with a newline (binary model) made multi-line error messages and odd file names.
TEST(FuzzRegressions, ColmapImageNameWithControlCharacter) {
  test::TempDir tmp;
  scene_with(tmp.path, kCam, "a.png");
  ColmapModel m = read_colmap(tmp / "sparse" / "0");
  m.images[0].name = "a\nb.png";
  write_colmap_bin(tmp / "bin", m);
  EXPECT_FILE_ERROR(read_colmap(tmp / "bin"), tmp / "bin" / "images.bin", "control characters");
}

// fuzz_text_embeddings_json: a non-number after the first value threw nlohmann::json::type_error, and 1e300 was
// cast to float (undefined behaviour).
TEST(FuzzRegressions, TextEmbeddingsNotNumbers) {
  for (const char* body : {R"({"cat": [0.5, "x"]})", R"({"cat": [0.5, 1e300]})", R"({"cat": [0.5, null]})"}) {
    test::TempDir tmp;
    scene_with(tmp.path, kCam, "a.png");
    atomic_write_text(tmp / "text_embeddings.json", body);
    EXPECT_FILE_ERROR(load_scene(tmp.path), tmp / "text_embeddings.json", "embedding of 'cat'");
  }
}
