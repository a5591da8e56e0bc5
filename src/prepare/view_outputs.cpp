// Per-view SAM masks, CLIP features and model depth (see view_outputs.h).
#include "prepare/view_outputs.h"

#include <fmt/format.h>

#include <memory>
#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "core/npy.h"
#include "core/progress.h"
#include "masks/rle.h"
#include "model/near_plane.h"
#include "model/ply.h"
#include "model/render_inputs.h"
#include "render/camera_from_view.h"
#include "render/renderer.h"
#include "train/registry.h"

namespace hgs::prepare {
namespace fs = std::filesystem;
namespace {

nlohmann::json sam_json(const std::vector<sam::AmgMask>& ms, int w, int h) {
  nlohmann::json list = nlohmann::json::array();
  for (const sam::AmgMask& m : ms) {
    masks::Rle r = masks::rle_encode(m.mask, w, h);
    list.push_back({{"segmentation", {{"size", {h, w}}, {"counts", masks::rle_counts_to_string(r.counts)}}},
                    {"area", m.area},
                    {"bbox", {m.bbox[0], m.bbox[1], m.bbox[2], m.bbox[3]}},
                    {"predicted_iou", m.predicted_iou},
                    {"point_coords", {{m.point[0], m.point[1]}}},
                    {"stability_score", m.stability_score},
                    {"crop_box", {0, 0, w, h}}});
  }
  return list;
}

}  // namespace

ViewFilesSummary write_sam_files(const Scene& s, const sam::SamModel& m, const sam::AmgOptions& amg,
                                 const fs::path& out_dir, bool force, bool progress) {
  const int n = amg.points_per_side * amg.points_per_side;
  const int batches = (n + amg.points_per_batch - 1) / amg.points_per_batch;
  Progress bar("sam masks", long(s.views.size()) * batches, progress);
  ViewFilesSummary r;
  int done = 0;
  for (const View& v : s.views) {
    const fs::path out = out_dir / (v.stem + ".json");
    if (!force && fs::exists(out)) {
      ++r.skipped;
    } else {
      Image img = s.load_image(v.index);
      sam::ImageEmbedding e = m.embed(img);
      std::vector<sam::AmgMask> ms = sam::generate_masks(m, e, amg, [&](int d, int) {
        bar.update(long(done) * batches + (d + amg.points_per_batch - 1) / amg.points_per_batch, v.stem);
      });
      ensure_dir(out.parent_path());
      atomic_write_text(out, sam_json(ms, img.width, img.height).dump());
      r.items += ms.size();
      r.per_view.push_back(int(ms.size()));
      ++r.written;
    }
    ++done;
    bar.update(long(done) * batches, fmt::format("{} masks", r.items));
  }
  bar.finish(fmt::format("{} masks", r.items));
  return r;
}

ViewFilesSummary write_clip_features(const Scene& s, const clip::ClipModel& m, const clip::DenseOptions& d, bool force,
                                     bool progress) {
  const fs::path out_dir = s.root / "features";
  Progress bar("clip features", long(s.views.size()), progress);
  ViewFilesSummary r;
  int done = 0;
  for (const View& v : s.views) {
    const fs::path out = out_dir / (v.stem + ".npy");
    if (!force && fs::exists(out)) {
      ++r.skipped;
    } else {
      Image img = s.load_image(v.index);
      clip::DenseFeatures f = m.dense_features(img, d);
      ensure_dir(out.parent_path());
      write_npy(out, make_npy_f16({size_t(f.h), size_t(f.w), size_t(f.dim)}, f.data.data()));
      r.grid_w = f.w, r.grid_h = f.h;
      ++r.written;
    }
    bar.update(++done, r.grid_h ? fmt::format("{}x{} grid", r.grid_w, r.grid_h) : "");
  }
  bar.finish();
  return r;
}

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
  train::TrainConfig cfg;
  cfg.iters = iters;
  std::unique_ptr<train::Trainer> t = train::make_trainer(scene, idx, cfg, "rgb", nullptr, progress);
  Progress bar("depth model", iters, progress);
  while (t->iteration() < iters) {
    train::StepInfo s = t->step();
    bar.update(t->iteration(), fmt::format("N {} {:.0f} ms/it", s.num_gaussians, s.ms));
  }
  bar.finish(fmt::format("{} Gaussians", t->model().n));
  ensure_dir(out_ply.parent_path());
  write_model_ply(out_ply, t->model());
}

}  // namespace hgs::prepare
