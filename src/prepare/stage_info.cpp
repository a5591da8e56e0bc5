// The input list's entries as arrays (see stage_info.h).
#include "prepare/stage_info.h"

namespace hgs::prepare {

void to_json(nlohmann::json& j, const InputEntry& e) {
  j = nlohmann::json::array({e.name, e.width, e.height, e.orientation, e.source});
}

void from_json(const nlohmann::json& j, InputEntry& e) {
  j.at(0).get_to(e.name), j.at(1).get_to(e.width), j.at(2).get_to(e.height), j.at(3).get_to(e.orientation);
  j.at(4).get_to(e.source);
}

std::string model_record(const std::filesystem::path& model, const std::filesystem::path& scene) {
  return model.empty() ? "" : model.lexically_relative(scene).string();
}

std::filesystem::path model_folder(const MappingInfo& m, const std::filesystem::path& scene) {
  if (!m.model_path.empty()) return scene / m.model_path;
  if (m.model.empty()) return {};
  return scene / "prepare" / "sparse" / std::filesystem::path(m.model).filename();
}

}  // namespace hgs::prepare
