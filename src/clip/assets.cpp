// Asset lookup: see assets.h for the search order.
#include "clip/assets.h"

#include <cstdlib>
#include <vector>

#include "core/error.h"

namespace hgs::clip {
namespace fs = std::filesystem;

std::filesystem::path find_asset(const std::string& rel) {
  std::vector<fs::path> tried;
  auto probe = [&](const fs::path& dir) -> bool {
    tried.push_back(dir);
    std::error_code ec;
    return fs::is_regular_file(dir / rel, ec);
  };
  if (const char* env = std::getenv("HGS_ASSETS"); env && *env) {
    if (probe(env)) return fs::path(env) / rel;
  }
  std::error_code ec;
  fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) {
    fs::path dir = exe.parent_path();
    for (int up = 0; up < 4 && !dir.empty(); ++up, dir = dir.parent_path()) {
      if (probe(dir / "assets")) return dir / "assets" / rel;
      if (probe(dir / "share" / "hgs" / "assets")) return dir / "share" / "hgs" / "assets" / rel;
      if (dir == dir.root_path()) break;
    }
  }
#ifdef HGS_SOURCE_DIR
  if (probe(fs::path(HGS_SOURCE_DIR) / "assets")) return fs::path(HGS_SOURCE_DIR) / "assets" / rel;
#endif
  std::string where;
  for (auto& t : tried) where += (where.empty() ? "" : ", ") + t.string();
  fail("asset {} not found (searched HGS_ASSETS, then {}); set HGS_ASSETS to the folder holding {}", rel, where, rel);
}

}  // namespace hgs::clip
