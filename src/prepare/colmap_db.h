// What COLMAP left in its database (WORK/database.db), read with SQLite: the pose stages check that each COLMAP
// step produced what it should, not only that it exited 0 (COLMAP 3.8 logs "database or disk is full" and still
// exits 0 when the disk fills during feature extraction).
#pragma once
#include <filesystem>
#include <set>
#include <string>

namespace hgs::prepare {

// Names of the images that have a row in `images` and in `keypoints` and `descriptors` (zero features count: a
// blank image has them). Fails naming the file when it cannot be opened or read as COLMAP's database.
std::set<std::string> images_with_features(const std::filesystem::path& database);

}  // namespace hgs::prepare
