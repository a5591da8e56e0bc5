// MODEL/config.json's near plane (see near_plane.h).
#include "model/near_plane.h"

#include <cmath>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/json_file.h"
#include "render/renderer.h"

namespace hgs {

float checked_near_plane(double value, const std::string& where) {
  if (!std::isfinite(value) || value <= 0 || value > 1e30)
    fail("{}: the near plane must be a number > 0, got {}", where, value);
  return float(value);
}

float model_near_plane(const std::filesystem::path& model_ply) {
  const std::filesystem::path config = model_ply.parent_path() / "config.json";
  if (!std::filesystem::exists(config)) return render::kDefaultNearPlane;
  const nlohmann::json j = read_json_file(config);
  if (!j.is_object() || !j.contains("near_plane")) return render::kDefaultNearPlane;
  if (!j["near_plane"].is_number()) fail("{}: 'near_plane' is not a number", config.string());
  return checked_near_plane(j["near_plane"].get<double>(), config.string() + ": 'near_plane'");
}

}  // namespace hgs
