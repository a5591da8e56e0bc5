// `hgs prepare`: from a folder of photos (or a video) to the scene folder `hgs train` reads, in stages:
//   input      photos / video frames -> SCENE/prepare/input/ (photos.h)
//   features   matching   mapping   undistort      COLMAP poses -> SCENE/images/, SCENE/sparse/0/ (poses.h)
//   sam  import  depth  associate                  with SAM weights: SAM's automatic masks of every view, imported,
//                                                  a short RGB training for depth, 3D association -> SCENE/masks/
//   clip  text                                     with CLIP weights: dense features -> SCENE/features/, phrases
//                                                  -> SCENE/text_embeddings.json
// Each stage is skipped when stages.h records it complete with the same key; the run ends with SCENE/prepare.json.
#pragma once
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "clip/model.h"
#include "masks/associate.h"
#include "prepare/photos.h"
#include "prepare/poses.h"
#include "sam/amg.h"

namespace hgs::prepare {

// Stage names in order, and the group each belongs to (--until takes a group or a stage).
const std::vector<std::pair<std::string, std::string>>& stage_groups();

struct PrepareOptions {
  std::filesystem::path input, scene;
  InputOptions in;
  PoseOptions pose;
  bool allow_partial = false;  // keep going when fewer than half the images register
  std::string until;           // last stage or group to run ("" = all)
  // Masks (SAM): empty load_sam = no masks. sam_key names the weights and options (stage key).
  std::function<sam::SamModel()> load_sam;
  std::string sam_key;
  sam::AmgOptions amg;
  int depth_iters = 1000;  // RGB steps of the depth model for association (0 = COLMAP points only)
  masks::AssociateOptions associate;
  // Language (CLIP): empty load_clip = no features.
  std::function<clip::ClipModel()> load_clip;
  std::string clip_key;
  clip::DenseOptions dense;
  std::vector<std::string> phrases;  // LERF's canonical phrases are added
  bool progress = true;
};

struct StageRun {
  std::string name;
  double seconds = 0;
  bool reused = false;  // complete from an earlier run
};

struct PrepareReport {
  nlohmann::json json;  // what SCENE/prepare.json holds
  std::vector<StageRun> stages;
  std::string text() const;  // one screen
};

PrepareReport run_prepare(const PrepareOptions& opt);

}  // namespace hgs::prepare
