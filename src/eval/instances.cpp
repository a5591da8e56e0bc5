// Instance ground truth: the objects' names (gt/objects.json, else masks/objects.json) parsed with clear errors,
// and per-object masks from the instance label map.
#include "eval/instances.h"

#include <algorithm>
#include <cctype>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/image.h"
#include "core/json_file.h"

namespace hgs::eval {

namespace fs = std::filesystem;

fs::path object_names_file(const fs::path& scene) {
  const fs::path truth = scene / "gt" / "objects.json";
  return fs::exists(truth) ? truth : scene / "masks" / "objects.json";
}

std::map<int, std::string> load_object_names(const fs::path& scene) {
  const fs::path file = object_names_file(scene);
  if (!fs::is_regular_file(file))
    fail("{}: file not found (object names; {} was tried first)", file.string(),
         (scene / "gt" / "objects.json").string());
  const nlohmann::json j = read_json_file(file);
  if (!j.is_object()) fail("{}: expected an object {{\"id\": \"name\", ...}}", file.string());
  std::map<int, std::string> names;
  for (auto it = j.begin(); it != j.end(); ++it) {
    const std::string& key = it.key();
    const bool digits = !key.empty() && key.size() <= 5 && std::all_of(key.begin(), key.end(), [](char c) {
      return std::isdigit(static_cast<unsigned char>(c));
    });
    const int id = digits ? std::stoi(key) : 0;
    if (id < 1 || id > 65535) fail("{}: key \"{}\" is not an object id in 1..65535", file.string(), key);
    if (!it.value().is_string() || it.value().get<std::string>().empty())
      fail("{}: the name of object {} must be a non-empty string", file.string(), key);
    if (!names.emplace(id, it.value().get<std::string>()).second)
      fail("{}: object id {} appears twice", file.string(), id);
  }
  if (names.empty()) fail("{}: no objects", file.string());
  return names;
}

std::vector<std::pair<std::string, int>> load_query_set(const fs::path& scene, const std::string& set,
                                                        const std::map<int, std::string>& names) {
  const fs::path file = scene / "gt" / "queries.json";
  if (!fs::is_regular_file(file))
    fail("{}: file not found (query sets; a scene of `hgs synth --world realistic` has them)", file.string());
  const nlohmann::json j = read_json_file(file);
  if (!j.is_object()) fail("{}: expected an object {{\"set\": {{\"phrase\": id, ...}}, ...}}", file.string());
  if (!j.contains(set) || !j[set].is_object()) {
    std::string sets;
    for (auto it = j.begin(); it != j.end(); ++it) sets += (sets.empty() ? "" : ", ") + it.key();
    fail("{}: no query set '{}' (it has: {})", file.string(), set, sets);
  }
  std::vector<std::pair<std::string, int>> out;
  for (auto it = j[set].begin(); it != j[set].end(); ++it) {
    if (!it.value().is_number_integer() || !names.count(it.value().get<int>()))
      fail("{}: query '{}' of set '{}' must name an object id of the scene", file.string(), it.key(), set);
    out.emplace_back(it.key(), it.value().get<int>());
  }
  return out;
}

InstanceLabels load_instance_masks(const fs::path& scene, const std::string& view_name,
                                   const std::map<int, std::string>& names, int expect_width, int expect_height,
                                   int downscale) {
  // gt/instances/<stem>.png (a PNG beside JPEG images), else under the image's own name.
  const fs::path by_stem = scene / "gt" / "instances" / (fs::path(view_name).stem().string() + ".png");
  const fs::path by_name = scene / "gt" / "instances" / view_name;
  const fs::path file = fs::is_regular_file(by_stem) ? by_stem : by_name;
  if (downscale < 1) fail("{}: downscale factor must be >= 1, got {}", file.string(), downscale);
  if (!fs::is_regular_file(file))
    fail("{}: file not found (instance map; {} was tried too)", by_name.string(), by_stem.string());
  LabelMap full = load_label_png(file);
  if (full.width < downscale || full.height < downscale)
    fail("{}: size {}x{} is smaller than the downscale factor {}", file.string(), full.width, full.height, downscale);
  const LabelMap lm = downscale_labels(full, downscale);
  if ((expect_width > 0 || expect_height > 0) && (lm.width != expect_width || lm.height != expect_height))
    fail("{}: instance map size {}x{}{} does not match the image size {}x{}", file.string(), lm.width, lm.height,
         downscale > 1 ? fmt::format(" (downscaled by {})", downscale) : "", expect_width, expect_height);
  InstanceLabels out;
  out.width = lm.width;
  out.height = lm.height;
  for (auto& [id, name] : names) {
    Mask m(lm.v.size());
    for (size_t i = 0; i < m.size(); ++i) m[i] = lm.v[i] == id ? 1 : 0;
    out.ids.push_back(id);
    out.names.push_back(name);
    out.masks.push_back(std::move(m));
  }
  return out;
}

}  // namespace hgs::eval
