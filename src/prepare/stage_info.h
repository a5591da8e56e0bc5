// What each stage of `hgs prepare` records when it completes (SCENE/prepare/state.json, stages.h) and the later
// stages and the report read back: one struct per stage, to and from JSON. SCENE/prepare.json is built from them.
#pragma once
#include <array>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

namespace hgs::prepare {

struct InputEntry {  // one image: JSON [name, width, height, orientation, source]
  std::string name;
  int width = 0, height = 0, orientation = 1;
  std::string source;
};
struct InputInfo {
  std::string path, kind;  // path: resolved (input_dir.h); kind: photos | video
  int images = 0;
  std::vector<std::string> not_images, bad, blurred, broken_links;
  std::vector<std::array<std::string, 2>> renamed;  // [source, name given to COLMAP] (names.h)
  int resized = 0, rotated = 0;
  std::vector<InputEntry> list;  // left out of prepare.json
};
struct MappingInfo {
  int images = 0, registered = 0;
  std::vector<std::string> dropped;
  int models = 0, cameras = 0, points = 0;
  double mean_reprojection_error_px = 0, mean_track_length = 0;
  std::string matcher;
  std::string settings = "default";  // COLMAP settings of the kept model: default | wide-baseline mapper | ...
  std::vector<std::string> retried;  // retries of a sparse capture: "<settings>: <registered> of <images>"
  std::string model_path;  // the kept model's folder relative to the scene ("" = none); left out of prepare.json
  std::string model;       // records written before model_path: the folder as that run saw it; left out too
};
// What MappingInfo::model_path records for a model folder inside `scene` (WORK/sparse/N, WORK/retry/sparse/N):
// its path relative to the scene, so that a run from another directory, or on a copy of the scene, reads this
// scene's model.
std::string model_record(const std::filesystem::path& model, const std::filesystem::path& scene);
// The model folder of `m` in `scene`. A record written before model_path (`model`: relative to the directory
// the first run started in, or absolute) named WORK/sparse/N: only its last part is used.
std::filesystem::path model_folder(const MappingInfo& m, const std::filesystem::path& scene);

struct MatchingInfo {
  std::string matcher;
};
struct SamInfo {
  int views = 0, written = 0;
};
struct ImportInfo {
  int views = 0;
  size_t masks = 0, hidden = 0;
};
struct DepthInfo {
  int iters = 0;
};
struct AssociateInfo {
  int objects = 0, masks = 0, views_with_masks = 0;
};
struct ClipInfo {
  int views = 0;
  std::array<int, 2> grid{};  // width, height
  int dim = 0;
};
struct TextInfo {
  std::vector<std::string> phrases;
};

void to_json(nlohmann::json& j, const InputEntry& e);
void from_json(const nlohmann::json& j, InputEntry& e);
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(InputInfo, path, kind, images, not_images, bad, blurred, broken_links,
                                                renamed, resized, rotated, list)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(MappingInfo, images, registered, dropped, models, cameras, points,
                                                mean_reprojection_error_px, mean_track_length, matcher, settings,
                                                retried, model_path, model)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(MatchingInfo, matcher)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(SamInfo, views, written)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(ImportInfo, views, masks, hidden)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(DepthInfo, iters)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(AssociateInfo, objects, masks, views_with_masks)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(ClipInfo, views, grid, dim)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE_WITH_DEFAULT(TextInfo, phrases)

}  // namespace hgs::prepare
