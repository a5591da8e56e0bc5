// make_trainer: RGB or hybrid trainer for a scene (see setup.h).
#include "hybrid/setup.h"

#include "core/error.h"
#include "hybrid/method.h"
#include "train/train_views.h"

namespace hgs::hybrid {

std::unique_ptr<train::Trainer> make_trainer(const Scene& scene, const std::vector<int>& idx, const train::TrainConfig& cfg,
                                             const std::optional<HybridConfig>& hybrid, bool progress) {
  if (idx.empty()) fail("{}: the scene has no training views", scene.root.string());
  auto views = train::load_train_views(scene, idx, progress);
  const float extent = scene_extent(scene, idx);
  GaussianModel init = init_from_points(scene.points, scene.point_colors, cfg.sh_degree);
  std::unique_ptr<train::Method> method;
  if (hybrid) method = std::make_unique<HybridMethod>(*hybrid, load_hybrid_data(scene, idx, *hybrid, progress), cfg.seed);
  return std::make_unique<train::Trainer>(cfg, std::move(init), std::move(views), extent, std::move(method));
}

}  // namespace hgs::hybrid
