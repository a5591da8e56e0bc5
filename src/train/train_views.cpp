// Scene views -> TrainViews (see train_views.h).
#include "train/train_views.h"

#include "core/parallel.h"
#include "render/camera_from_view.h"

namespace hgs::train {

std::vector<TrainView> load_train_views(const Scene& scene, const std::vector<int>& idx, bool progress,
                                        float near_plane) {
  std::vector<TrainView> views(idx.size());
  parallel_for_progress("load images", long(idx.size()), progress, [&](long i) {
    const View& v = scene.views[idx[i]];
    views[i].name = v.name;
    views[i].cam = render::camera_from_view(v, near_plane);
    views[i].image = scene.load_image(idx[i]);
  });
  return views;
}

}  // namespace hgs::train
