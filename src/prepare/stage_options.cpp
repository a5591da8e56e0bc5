// Stage options as JSON and the stage keys (see stage_options.h). Each to_json lists every field of its struct;
// field_counts fails to compile when a field is added to one of the library's option structs, whose JSON here
// must then list it.
#include "prepare/stage_options.h"

#include "prepare/stages.h"

namespace hgs::sam {
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(AmgOptions, points_per_side, points_per_batch, pred_iou_thresh,
                                   stability_score_thresh, stability_score_offset, box_nms_thresh, min_mask_region_area)
}  // namespace hgs::sam

namespace hgs::clip {
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(DenseOptions, input_size, max_tokens, tile_size, normalize)
}  // namespace hgs::clip

namespace hgs::prepare {
namespace {

// Each structured binding names every field of its struct, so it stops compiling when one is added.
[[maybe_unused]] void field_counts(const sam::AmgOptions& amg, const clip::DenseOptions& dense,
                                   const masks::AssociateOptions& assoc) {
  [[maybe_unused]] auto& [a0, a1, a2, a3, a4, a5, a6] = amg;
  [[maybe_unused]] auto& [d0, d1, d2, d3] = dense;
  [[maybe_unused]] auto& [m0, m1, m2, m3, m4, m5, m6, m7, m8, m9, m10, m11, m12, m13, m14, m15, m16, m17, m18, m19, m20,
                          m21, m22] = assoc;
}

}  // namespace

NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(FeaturesStage, camera_model, max_features)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(MatchingStage, matcher, vocab_tree)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(SamStage, model, amg)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(DepthStage, iters)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(ClipStage, model, dense)
NLOHMANN_DEFINE_TYPE_NON_INTRUSIVE(TextStage, model, phrases)

// The association's parameters: every field of masks::AssociateOptions but scene, out_masks, names, depth, force,
// progress, tracks and track_split, which the stage sets itself (names: none; tracks: off, SAM's masks are per
// view).
void to_json(nlohmann::json& j, const AssociateStage& s) {
  const masks::AssociateOptions& a = s.associate;
  j = {
      {"min_affinity", a.min_affinity},     {"min_views", a.min_views},         {"min_points", a.min_points},
      {"core_margin", a.core_margin},       {"max_area", a.max_area},           {"attach", a.attach},
      {"join_parts", a.join_parts},         {"part_merge", a.part_merge},       {"whole_pixels", a.whole_pixels},
      {"edge_ramp", a.edge_ramp},           {"part_fraction", a.part_fraction}, {"drop_surfaces", a.drop_surfaces},
      {"surface_spread", a.surface_spread}, {"depth_stride", a.depth_stride},   {"depth_tolerance", a.depth_tolerance}};
}
void from_json(const nlohmann::json& j, AssociateStage& s) {
  masks::AssociateOptions& a = s.associate;
  j.at("min_affinity").get_to(a.min_affinity), j.at("min_views").get_to(a.min_views);
  j.at("min_points").get_to(a.min_points), j.at("core_margin").get_to(a.core_margin);
  j.at("max_area").get_to(a.max_area), j.at("attach").get_to(a.attach);
  j.at("join_parts").get_to(a.join_parts), j.at("part_merge").get_to(a.part_merge);
  j.at("whole_pixels").get_to(a.whole_pixels), j.at("edge_ramp").get_to(a.edge_ramp);
  j.at("part_fraction").get_to(a.part_fraction), j.at("drop_surfaces").get_to(a.drop_surfaces);
  j.at("surface_spread").get_to(a.surface_spread), j.at("depth_stride").get_to(a.depth_stride);
  j.at("depth_tolerance").get_to(a.depth_tolerance);
}

void to_json(nlohmann::json& j, const StageOptions& o) {
  const nlohmann::json none = nlohmann::json::object();
  j = {{"features", o.features}, {"matching", o.matching},   {"mapping", none}, {"retry_mapping", none},
       {"retry_features", none}, {"undistort", none},        {"sam", o.sam},    {"import", none},
       {"depth", o.depth},       {"associate", o.associate}, {"clip", o.clip},  {"text", o.text}};
}

void from_json(const nlohmann::json& j, StageOptions& o) {
  j.at("features").get_to(o.features), j.at("matching").get_to(o.matching), j.at("sam").get_to(o.sam);
  j.at("depth").get_to(o.depth), j.at("associate").get_to(o.associate), j.at("clip").get_to(o.clip);
  j.at("text").get_to(o.text);
}

const std::vector<std::pair<std::string, std::vector<std::string>>>& stage_inputs() {
  static const std::vector<std::pair<std::string, std::vector<std::string>>> s = {{"features", {"input"}},
                                                                                  {"matching", {"features"}},
                                                                                  {"mapping", {"matching"}},
                                                                                  {"retry_mapping", {"mapping"}},
                                                                                  {"retry_features", {"retry_mapping"}},
                                                                                  {"undistort", {"retry_features"}},
                                                                                  {"sam", {"undistort"}},
                                                                                  {"import", {"sam"}},
                                                                                  {"depth", {"undistort"}},
                                                                                  {"associate", {"import", "depth"}},
                                                                                  {"clip", {"undistort"}},
                                                                                  {"text", {}}};
  return s;
}

std::map<std::string, std::string> stage_keys(const StageOptions& o, const std::string& input_key) {
  const nlohmann::json options = o;
  std::map<std::string, std::string> keys{{"input", input_key}};
  for (const auto& [name, inputs] : stage_inputs()) {
    std::string text = name + "|" + options.at(name).dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
    for (const std::string& d : inputs) text += "|" + keys.at(d);
    keys[name] = hash_key(text);
  }
  return keys;
}

}  // namespace hgs::prepare
