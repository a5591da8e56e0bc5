// The training views of a scene for a Trainer: each view's camera (render::camera_from_view) and its image,
// downscaled as the scene says.
#pragma once
#include <vector>

#include "scene/scene.h"
#include "train/trainer.h"

namespace hgs::train {

// Loads the training images of `idx` in parallel, with a progress bar when `progress`; the cameras cull at
// `near_plane` (TrainConfig::near_plane).
std::vector<TrainView> load_train_views(const Scene& scene, const std::vector<int>& idx, bool progress,
                                        float near_plane = render::kDefaultNearPlane);

}  // namespace hgs::train
