// The trainer factory of `hgs train` / `hgs ablate`: loads the training views (train::load_train_views; for the
// hybrid method also masks and features), initialises Gaussians from the SfM points and returns the
// train::Trainer with the RGB or the hybrid method. It lives in hybrid/, the top of the training stack, because
// it knows both methods (train/ must not know hybrid/).
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

}  // namespace hgs::hybrid
