// Per-view outputs shared by `hgs prepare` and the single-stage commands (`hgs masks generate`, `hgs features`,
// `hgs masks associate --depth-model`): each view's file is written atomically and a view whose file exists is
// skipped unless `force`, so an interrupted run resumes.
#pragma once
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "clip/model.h"
#include "sam/amg.h"
#include "scene/scene.h"

namespace hgs::prepare {

struct ViewFilesSummary {
  int written = 0, skipped = 0;
  size_t items = 0;            // masks written (SAM); 0 for features
  std::vector<int> per_view;   // [views written] masks per view (SAM)
  int grid_w = 0, grid_h = 0;  // last feature grid (CLIP)
};

// SAM's automatic masks of every view -> out_dir/<stem>.json (SAM JSON: COCO RLE, what `hgs masks import
// --from sam-json` reads).
ViewFilesSummary write_sam_files(const Scene& scene, const sam::SamModel& model, const sam::AmgOptions& amg,
                                 const std::filesystem::path& out_dir, bool force, bool progress);

// Dense CLIP features of every view -> SCENE/features/<stem>.npy, float16 [h, w, D].
ViewFilesSummary write_clip_features(const Scene& scene, const clip::ClipModel& model, const clip::DenseOptions& d,
                                     bool force, bool progress);

// Depth of each view from a trained model (folder with point_cloud.ply, or a PLY): the expected depth
// sum_n z_n alpha_n T_n / alpha where its opacity alpha >= 0.5, else 0 (none). [H, W] per view.
std::function<std::vector<float>(const View&)> depth_from_model(const std::filesystem::path& model);

// `iters` steps of plain 3DGS (`--method rgb`) on every view of the scene, written to out_ply: the depth model
// `hgs masks associate --depth-model` links masks through.
void train_depth_model(const Scene& scene, int iters, const std::filesystem::path& out_ply, bool progress);

}  // namespace hgs::prepare
