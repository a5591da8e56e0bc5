// Locating files shipped in the repository's assets/ folder at run time. Search order: the directory named by
// the environment variable HGS_ASSETS, then assets/ beside the executable (and its parents up to three levels,
// which covers build-*/ trees inside the source tree and <prefix>/share/hgs/assets for installs), then the
// source tree the library was compiled from (HGS_SOURCE_DIR/assets).
#pragma once
#include <filesystem>
#include <string>

namespace hgs::clip {

// Returns the path of assets/<rel>; throws hgs::Error listing the places searched when it is absent.
std::filesystem::path find_asset(const std::string& rel);

}  // namespace hgs::clip
