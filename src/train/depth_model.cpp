// Depth model training and its per-view depth (see depth_model.h).
#include "train/depth_model.h"

#include <fmt/format.h>

#include <memory>

#include "core/fs.h"
#include "core/progress.h"
#include "model/near_plane.h"
#include "model/ply.h"
#include "model/render_inputs.h"
#include "render/camera_from_view.h"
#include "render/renderer.h"
#include "train/registry.h"

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

void train_depth_model(const Scene& scene, int iters, const fs::path& out_ply, bool progress) {
  std::vector<int> idx(scene.views.size());
  for (size_t i = 0; i < idx.size(); ++i) idx[i] = int(i);
  TrainConfig cfg;
  cfg.iters = iters;
  std::unique_ptr<Trainer> t = make_trainer(scene, idx, cfg, "rgb", nullptr, progress);
  Progress bar("depth model", iters, progress);
  while (t->iteration() < iters) {
    StepInfo s = t->step();
    bar.update(t->iteration(), fmt::format("N {} {:.0f} ms/it", s.num_gaussians, s.ms));
  }
  bar.finish(fmt::format("{} Gaussians", t->model().n));
  ensure_dir(out_ply.parent_path());
  write_model_ply(out_ply, t->model());
}

}  // namespace hgs::train
