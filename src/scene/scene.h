// A capture on disk (see docs/formats.md): COLMAP model + images, and optional masks, mask confidences,
// dense language features, text embeddings and evaluation labels. `load_scene` reads the model and checks
// that every listed file exists; pixels are loaded per view on demand.
#pragma once
#include <Eigen/Core>
#include <algorithm>
#include <cstddef>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/image.h"

namespace hgs {

struct View {
  int index = 0;  // position in Scene::views (sorted by name)
  int colmap_id = 0;
  std::string name;                       // as in the COLMAP model, relative to images/ (may contain sub-folders)
  std::string stem;                       // name without extension: masks/<stem>.png, features/<stem>.npy
  int width = 0, height = 0;              // after downscaling
  double fx = 0, fy = 0, cx = 0, cy = 0;  // after downscaling (pixel-centre convention)
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // world -> camera
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  bool is_test = false;
  std::filesystem::path image_path;  // file read for this view (maybe images_F/)
  std::optional<std::filesystem::path> mask_path, conf_path, feature_path;

  Eigen::Vector3d camera_center() const { return -R.transpose() * t; }
};

struct SceneOptions {
  int downscale = 1;              // integer area downscale of images (and masks, features follow the image)
  bool cache_downscaled = false;  // write SCENE/images_F/ for later runs
};

struct Scene {
  std::filesystem::path root;
  int downscale = 1;
  std::vector<View> views;                                    // sorted by name
  std::vector<Eigen::Vector3f> points;                        // [P, 3] sparse SfM points
  std::vector<Eigen::Vector3f> point_colors;                  // [P, 3] in [0, 1]
  std::map<int, std::string> object_names;                    // masks/objects.json
  std::map<std::string, std::vector<float>> text_embeddings;  // text_embeddings.json
  std::string split_source;                                   // "test.txt" or "every 8th view (LLFF)"
  std::vector<std::string> warnings;                          // non-fatal problems found while loading

  std::vector<int> train_indices() const;
  std::vector<int> test_indices() const;
  bool has_masks() const;
  bool has_features() const;
  std::filesystem::path label_dir() const { return root / "label"; }
  std::filesystem::path segmentation_dir() const { return root / "segmentations"; }

  // Pixel loading, resampled to the view's (downscaled) resolution.
  Image load_image(int view) const;                                   // [H, W, 3]
  std::optional<LabelMap> load_mask(int view) const;                  // [H, W] object ids, 0 = background
  std::optional<std::vector<float>> load_confidence(int view) const;  // [H, W]
  // Dense features bilinearly upsampled to the image: [H, W, D] (D returned in `dim`).
  std::optional<std::vector<float>> load_features(int view, int& dim) const;
  // The stored feature grid as it is on disk (checked): [h, w, D].
  std::optional<std::vector<float>> load_feature_grid(int view, int& h, int& w, int& dim) const;
  // Largest object id over all masks (reads every mask once, then cached).
  int num_objects() const;

 private:
  mutable int num_objects_cache_ = -1;
};

Scene load_scene(const std::filesystem::path& root, const SceneOptions& opt = {});

// 3DGS's "cameras extent": 1.1 x the largest distance of a camera centre from the mean camera centre, over
// the given views (all views when `views` is empty).
float scene_extent(const Scene& scene, const std::vector<int>& views = {});

// Bilinear resampling of a [h, w, D] grid to [H, W, D], aligning pixel centres (align_corners = false).
std::vector<float> upsample_bilinear(const float* src, int h, int w, int d, int H, int W);

// One pixel of upsample_bilinear without the [H, W, D] output: the grid rows of the four corners and their
// weights (bilinear_tap), and the pixel's D values from them (bilinear_sample), the same operations, so the same
// bits. For passes that reduce the upsampled map as they go (hybrid/assign.h: pool_reference_upsampled).
struct BilinearTap {
  const float *p00, *p01, *p10, *p11;
  float w00, w01, w10, w11;
};
inline BilinearTap bilinear_tap(const float* src, int h, int w, int d, int H, int W, int x, int y) {
  const float sy = float(h) / H, sx = float(w) / W;
  const float fy = std::clamp((y + 0.5f) * sy - 0.5f, 0.f, float(h - 1));
  const int y0 = static_cast<int>(fy), y1 = std::min(y0 + 1, h - 1);
  const float ay = fy - y0;
  const float fx = std::clamp((x + 0.5f) * sx - 0.5f, 0.f, float(w - 1));
  const int x0 = static_cast<int>(fx), x1 = std::min(x0 + 1, w - 1);
  const float ax = fx - x0;
  return {src + (size_t(y0) * w + x0) * d,
          src + (size_t(y0) * w + x1) * d,
          src + (size_t(y1) * w + x0) * d,
          src + (size_t(y1) * w + x1) * d,
          (1 - ay) * (1 - ax),
          (1 - ay) * ax,
          ay * (1 - ax),
          ay * ax};
}
inline void bilinear_sample(const BilinearTap& t, int d, float* out) {  // out [d]
  for (int c = 0; c < d; ++c) out[c] = t.w00 * t.p00[c] + t.w01 * t.p01[c] + t.w10 * t.p10[c] + t.w11 * t.p11[c];
}
// Pixel p (its row-major index in the H x W image) of upsample_bilinear's map: out [d], returned.
inline const float* bilinear_pixel(const float* src, int h, int w, int d, int H, int W, size_t p, float* out) {
  bilinear_sample(bilinear_tap(src, h, w, d, H, W, int(p % size_t(W)), int(p / size_t(W))), d, out);
  return out;
}

}  // namespace hgs
