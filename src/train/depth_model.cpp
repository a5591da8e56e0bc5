// Depth model training and its per-view depth (see depth_model.h).
#include "train/depth_model.h"

#include <memory>

#include "model/near_plane.h"
#include "model/ply.h"
#include "model/render_inputs.h"
#include "render/camera_from_view.h"
#include "render/renderer.h"
#include "train/registry.h"
#include "train/run.h"

namespace hgs::train {
namespace fs = std::filesystem;

std::function<std::vector<float>(const View&)> depth_from_model(const fs::path& model_arg) {
  const fs::path ply = fs::is_directory(model_arg) ? model_arg / "point_cloud.ply" : model_arg;
  auto model = std::make_shared<GaussianModel>(read_model_ply(ply));
  auto renderer = std::make_shared<render::GaussianRenderer>();
  const float near_plane = model_near_plane(ply);
  return [model, renderer, near_plane](const View& v) {
    render::GaussianInputs in = render_inputs(*model);
    render::RenderSettings rs;
    rs.want_depth = true;
    render::RenderOutputs out;
    renderer->forward(render::camera_from_view(v, near_plane), in, rs, out);
    std::vector<float> d(out.alpha.size(), 0.f);
    for (size_t p = 0; p < d.size(); ++p)
      if (out.alpha[p] >= 0.5f) d[p] = out.depth[p] / out.alpha[p];
    return d;
  };
}

void train_depth_model(const Scene& scene, int iters, const fs::path& out, bool progress) {
  std::vector<int> idx(scene.views.size());
  for (size_t i = 0; i < idx.size(); ++i) idx[i] = int(i);
  TrainConfig cfg;  // the 30k schedule: densification starts at image 500 as in 3DGS, whatever `iters`
  cfg.iters = iters;
  std::unique_ptr<Trainer> t = make_trainer(scene, idx, cfg, "rgb", nullptr, progress);
  RunOptions ro;
  ro.out = out;
  ro.progress = progress;
  ro.label = "depth model";
  TrainingRun run(*t, scene, ro, run_config(*t, scene, nullptr, t->model().n));
  run.train();
  run.save();
}

}  // namespace hgs::train
