// Fixtures for the masks tests: a tiny scene (COLMAP model + grey images) and small file writers.
#pragma once
#include <filesystem>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/npy.h"
#include "scene/colmap.h"

namespace hgs::test {

// SCENE with images/<name> (width x height grey PNGs) and sparse/0 listing them (one PINHOLE camera, no points).
inline void make_tiny_scene(const std::filesystem::path& root, const std::vector<std::string>& names, int width,
                            int height) {
  ColmapModel m;
  m.cameras[1] = ColmapCamera{
      1, "PINHOLE", uint64_t(width), uint64_t(height), {double(width), double(width), width / 2.0, height / 2.0}};
  int id = 1;
  for (auto& n : names) {
    ColmapImage im;
    im.id = id++;
    im.camera_id = 1;
    im.name = n;
    im.tvec = Eigen::Vector3d(0, 0, 1.0 + id);
    m.images.push_back(im);
    save_png(root / "images" / n, Image(width, height, 3, 0.5f));
  }
  write_colmap_bin(root / "sparse" / "0", m);
}

// A float32 NPY with any shape.
inline void write_f32(const std::filesystem::path& p, const std::vector<size_t>& shape, const std::vector<float>& v) {
  write_npy(p, make_npy_f32(shape, v.data()));
}

}  // namespace hgs::test
