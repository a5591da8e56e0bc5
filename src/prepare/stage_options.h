// The options of each stage of `hgs prepare` after the input: everything a stage's outputs depend on besides the
// outputs of the stages it reads, and the only place the stage reads its settings from. A stage's key (stages.h)
// hashes these options as JSON with the keys of the stages it reads, so a change of any field reruns that stage and
// the stages downstream of it, and no other.
#pragma once
#include <map>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "clip/model.h"
#include "masks/associate.h"
#include "sam/amg.h"

namespace hgs::prepare {

struct FeaturesStage {
  std::string camera_model;
  int max_features = 0;
};
struct MatchingStage {
  std::string matcher;     // resolved: exhaustive | sequential | vocab-tree
  std::string vocab_tree;  // vocabulary tree file ("" = none)
};
struct SamStage {
  std::string model;  // the weights' identity and the model's options
  sam::AmgOptions amg;
};
struct DepthStage {
  int iters = 0;  // RGB steps of the depth model (0 = none)
};
struct AssociateStage {
  masks::AssociateOptions associate;  // its parameters; the paths, depth and flags are the stage's own
};
struct ClipStage {
  std::string model;  // the weights' identity and the model's options
  clip::DenseOptions dense;
};
struct TextStage {
  std::string model;                 // the weights' identity and the model's options
  std::vector<std::string> phrases;  // in order, LERF's canonical ones included
};

// The mapping, retry_mapping, retry_features (COLMAP's wide-baseline settings: constants of poses.h), undistort
// and import stages have no options of their own.
struct StageOptions {
  FeaturesStage features;
  MatchingStage matching;
  SamStage sam;
  DepthStage depth;
  AssociateStage associate;
  ClipStage clip;
  TextStage text;
};

void to_json(nlohmann::json& j, const StageOptions& o);  // {"<stage>": {options}} for every stage after input
void from_json(const nlohmann::json& j, StageOptions& o);

// The stages after input in order, each with the stages whose outputs it reads.
const std::vector<std::pair<std::string, std::vector<std::string>>>& stage_inputs();

// The key of every stage after input: a hash of its name, its options and the keys of the stages it reads.
std::map<std::string, std::string> stage_keys(const StageOptions& o, const std::string& input_key);

}  // namespace hgs::prepare
