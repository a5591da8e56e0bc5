// Ground truth for the `instances` protocol: the names of the objects of SCENE/gt/objects.json ({"1": "red mug",
// ...}; written by `hgs synth`) and the exact instance maps SCENE/gt/instances/<stem>.png, or <view name> when that
// is missing (label PNG, 0 = background, k = object k). A scene without gt/objects.json (a real capture whose
// masks/objects.json names the ids of gt/instances) takes the names from masks/objects.json.
#pragma once
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include "eval/metrics.h"

namespace hgs::eval {

// The file the objects' names come from: SCENE/gt/objects.json, else SCENE/masks/objects.json (the fallback for
// scenes without gt/objects.json; it names the training masks' ids, which must then be gt/instances' ids).
std::filesystem::path object_names_file(const std::filesystem::path& scene);
// id -> name, from object_names_file(scene). Keys must be integers in 1..65535, values non-empty strings.
std::map<int, std::string> load_object_names(const std::filesystem::path& scene);

// A named query set of SCENE/gt/queries.json ({set: {phrase: object id}}; written by `hgs synth`'s realistic
// world): (phrase, object id) pairs in phrase order. Fails naming the file and the sets it has when `set` is
// missing, and naming the phrase when an id is not an object of `names`.
std::vector<std::pair<std::string, int>> load_query_set(const std::filesystem::path& scene, const std::string& set,
                                                        const std::map<int, std::string>& names);

struct InstanceLabels {
  int width = 0, height = 0;
  std::vector<int> ids;            // [K] object ids, ascending (every object of `names`)
  std::vector<std::string> names;  // [K]
  std::vector<Mask> masks;         // [K] masks [H, W] 0/1 (all zero when the object is not visible)
};
// Masks of every named object in one view. downscale F >= 1 takes the centre pixel of each F x F block
// (hgs::downscale_labels); expect_* > 0: the (downscaled) size must match.
InstanceLabels load_instance_masks(const std::filesystem::path& scene, const std::string& view_name,
                                   const std::map<int, std::string>& names, int expect_width = 0, int expect_height = 0,
                                   int downscale = 1);

}  // namespace hgs::eval
