// The body of the COLMAP harnesses (fuzz_colmap_bin.cpp, fuzz_colmap_txt.cpp): writes the three model files of
// a scene skeleton, parses them with read_colmap (what load_scene calls), then, with an (empty) image file made
// for every image name the model lists, loads the whole scene with load_scene as the CLI does.
#pragma once
#include <filesystem>
#include <system_error>

#include "core/error.h"
#include "fuzz.h"
#include "scene/colmap.h"
#include "scene/scene.h"

namespace hgs::fuzz {

inline int colmap_scene(const uint8_t* data, size_t size, const char* ext) {
  namespace fs = std::filesystem;
  const fs::path scene = scratch(std::string("colmap") + ext);
  const auto parts = split(data, size, 3);
  const char* names[3] = {"cameras", "images", "points3D"};
  for (int i = 0; i < 3; ++i) put_file(scene / "sparse" / "0" / (std::string(names[i]) + ext), parts[i]);
  fs::create_directories(scene / "images");
  try {
    const ColmapModel m = read_colmap(scene / "sparse" / "0");
    for (const ColmapImage& im : m.images) {  // a name that cannot be a file is left out (load_scene then fails)
      const fs::path p = fs::path(im.name).lexically_normal();
      if (im.name.empty() || im.name.size() > 200 || p.is_absolute() || p.empty() || *p.begin() == "..") continue;
      std::error_code ec;
      fs::create_directories((scene / "images" / p).parent_path(), ec);
      if (!ec && !fs::exists(scene / "images" / p, ec)) put_file(scene / "images" / p, "");
    }
    load_scene(scene);
  } catch (const Error&) {
  }
  return 0;
}

}  // namespace hgs::fuzz
