// Building a trainer for a scene: loads the training images (and, for the hybrid method, masks and
// features), initialises Gaussians from the SfM points and returns the Trainer with the RGB or the hybrid method.
#pragma once
#include <memory>
#include <optional>

#include "hybrid/config.h"
#include "scene/scene.h"
#include "train/trainer.h"

namespace hgs::hybrid {

// hybrid == nullopt: plain 3DGS RGB training.
std::unique_ptr<train::Trainer> make_trainer(const Scene& scene, const std::vector<int>& train_views,
                                             const train::TrainConfig& cfg, const std::optional<HybridConfig>& hybrid,
                                             bool progress);

// Loads the training images of `idx` (downscaled by the scene) in parallel, with a progress bar.
std::vector<train::TrainView> load_train_views(const Scene& scene, const std::vector<int>& idx, bool progress);

}  // namespace hgs::hybrid
