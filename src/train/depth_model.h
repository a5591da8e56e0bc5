// The depth model: a short plain-3DGS training on every view, whose rendered depth links masks across views
// (`hgs masks associate --depth-model`, `hgs prepare`'s depth stage).
#pragma once
#include <filesystem>
#include <functional>
#include <vector>

#include "scene/scene.h"

namespace hgs::train {

// Depth of each view from a trained model (folder with point_cloud.ply, or a PLY): the expected depth
// sum_n z_n alpha_n T_n / alpha where its opacity alpha >= 0.5, else 0 (none). [H, W] per view.
std::function<std::vector<float>(const View&)> depth_from_model(const std::filesystem::path& model);

// `iters` steps of plain 3DGS (`--method rgb`) on every view of the scene through the training run (train/run.h),
// written to the model folder `out` (point_cloud.ply, config.json, train_stats.json).
void train_depth_model(const Scene& scene, int iters, const std::filesystem::path& out, bool progress);

}  // namespace hgs::train
