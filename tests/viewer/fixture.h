// A tiny synthetic scene plus a hand-built hybrid model whose queries have known answers: every Gaussian
// (one per SfM point) gets the ground-truth object seen at its projection in most views (one-hot q, hard id)
// and that object's class-name text embedding as its language feature, so "red mug" picks the red mug.
#pragma once
#include <filesystem>
#include <map>
#include <string>

namespace hgs::test {

struct ViewerFixture {
  std::filesystem::path scene, model;     // scene folder, model PLY
  std::map<int, std::string> names;       // object id -> name (masks/objects.json)
  std::map<int, int> counts;              // object id -> Gaussians with that hard id
};

// Writes the scene (via `hgs synth`) and the model into `dir`.
ViewerFixture make_viewer_fixture(const std::filesystem::path& dir);

}  // namespace hgs::test
