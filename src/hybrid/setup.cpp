#include "hybrid/setup.h"

#include "core/error.h"
#include "core/parallel.h"
#include "hybrid/method.h"

namespace hgs::hybrid {

std::vector<train::TrainView> load_train_views(const Scene& scene, const std::vector<int>& idx, bool progress) {
  std::vector<train::TrainView> views(idx.size());
  parallel_for_progress("load images", long(idx.size()), progress, [&](long i) {
    const View& v = scene.views[idx[i]];
    views[i].name = v.name;
    views[i].cam = train::make_camera(v);
    views[i].image = scene.load_image(idx[i]);
  });
  return views;
}

std::unique_ptr<train::Trainer> make_trainer(const Scene& scene, const std::vector<int>& idx, const train::TrainConfig& cfg,
                                             const std::optional<HybridConfig>& hybrid, bool progress) {
  if (idx.empty()) fail("{}: the scene has no training views", scene.root.string());
  auto views = load_train_views(scene, idx, progress);
  const float extent = scene_extent(scene, idx);
  GaussianModel init = init_from_points(scene.points, scene.point_colors, cfg.sh_degree);
  std::unique_ptr<train::Method> method;
  if (hybrid) method = std::make_unique<HybridMethod>(*hybrid, load_hybrid_data(scene, idx, *hybrid, progress), cfg.seed);
  return std::make_unique<train::Trainer>(cfg, std::move(init), std::move(views), extent, std::move(method));
}

}  // namespace hgs::hybrid
