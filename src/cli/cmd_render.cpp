// `hgs render SCENE MODEL --out DIR`: renders a trained model at the scene's views of a split, writes
// DIR/renders/<stem>.png, DIR/compare/<stem>.png (ground truth | render) and DIR/metrics.json with PSNR and
// SSIM per view and their means.
#include <omp.h>

#include <nlohmann/json.hpp>

#include "cli/command.h"
#include "core/error.h"
#include "core/fs.h"
#include "core/json_file.h"
#include "core/progress.h"
#include "model/near_plane.h"
#include "model/ply.h"
#include "model/render_inputs.h"
#include "render/camera_from_view.h"
#include "render/renderer.h"
#include "scene/scene.h"
#include "train/held_out.h"
#include "train/ssim.h"

namespace hgs::cli {
namespace {

struct RenderArgs {
  std::string scene, model, out, split = "test";
  int downscale = 1, threads = 0;
  float near_plane = 0;  // 0: as MODEL/config.json says
  bool white_bg = false, black_bg = false, quiet = false;
};

void run_render(const RenderArgs& a) {
  set_threads(a.threads);
  fs::path model_path = a.model;
  fs::path config_path;
  if (fs::is_directory(model_path)) {
    config_path = model_path / "config.json";
    model_path /= "point_cloud.ply";
  }
  bool white = false;
  if (!config_path.empty() && fs::exists(config_path)) {
    const nlohmann::json j = read_json_file(config_path);
    if (j.contains("white_bg") && j["white_bg"].is_boolean()) white = j["white_bg"].get<bool>();
  }
  if (a.white_bg) white = true;
  if (a.black_bg) white = false;
  const float near_plane = a.near_plane > 0 ? a.near_plane : model_near_plane(model_path);
  GaussianModel model = read_model_ply(model_path);
  Scene scene = load_scene(a.scene, {a.downscale, false});
  std::vector<int> idx;
  if (a.split == "test") idx = scene.test_indices();
  else if (a.split == "train") idx = scene.train_indices();
  else
    for (auto& v : scene.views) idx.push_back(v.index);
  if (idx.empty()) fail("{}: the {} split has no views", a.scene, a.split);

  const fs::path out = a.out;
  ensure_dir(out / "renders");
  ensure_dir(out / "compare");
  render::GaussianRenderer renderer;
  render::RenderOutputs ro;
  render::GaussianInputs in = render_inputs(model);
  render::RenderSettings rs;
  rs.want_depth = false;
  rs.background[0] = rs.background[1] = rs.background[2] = white ? 1.f : 0.f;
  train::SsimWorkspace<float> ws;
  nlohmann::json per_view = nlohmann::json::array();
  double sum_psnr = 0, sum_ssim = 0;
  Progress bar("render", long(idx.size()), !a.quiet);
  for (size_t k = 0; k < idx.size(); ++k) {
    const View& v = scene.views[idx[k]];
    Image gt = scene.load_image(v.index);
    renderer.forward(render::camera_from_view(v, near_plane), in, rs, ro);
    Image img;
    const train::ViewScore score = train::score_view(ro.rgb, gt, img, ws);
    const float psnr = score.psnr, ssim = score.ssim;
    sum_psnr += psnr;
    sum_ssim += ssim;
    per_view.push_back({{"name", v.name}, {"psnr", psnr}, {"ssim", ssim}});
    fs::path rp = out / "renders" / (v.stem + ".png"), cp = out / "compare" / (v.stem + ".png");
    ensure_dir(rp.parent_path());
    ensure_dir(cp.parent_path());
    save_png(rp, img);
    Image side(2 * v.width, v.height, 3);
    for (int y = 0; y < v.height; ++y)
      for (int x = 0; x < v.width; ++x)
        for (int c = 0; c < 3; ++c) {
          side.at(x, y, c) = gt.at(x, y, c);
          side.at(x + v.width, y, c) = img.at(x, y, c);
        }
    save_png(cp, side);
    bar.update(long(k + 1), fmt::format("psnr {:.2f}", psnr));
  }
  const double nv = double(idx.size());
  nlohmann::json metrics = {
      {"split", a.split},           {"model", fs::absolute(model_path).lexically_normal().string()},
      {"num_views", idx.size()},    {"num_gaussians", model.n},
      {"near_plane", near_plane},   {"mean_psnr", sum_psnr / nv},
      {"mean_ssim", sum_ssim / nv}, {"views", per_view}};
  atomic_write_text(out / "metrics.json", metrics.dump(2) + "\n");
  bar.finish();
  if (!a.quiet)
    fmt::print("{} {} views: PSNR {:.2f} dB, SSIM {:.4f} -> {}\n", idx.size(), a.split, sum_psnr / nv, sum_ssim / nv,
               (out / "metrics.json").string());
}

CommandRegistration reg(
    {"render", "Render a trained model at a scene's views; PSNR/SSIM metrics", 30, [](CLI::App& sub) {
       auto a = std::make_shared<RenderArgs>();
       sub.add_option("SCENE", a->scene, "Scene folder")->required();
       sub.add_option("MODEL", a->model, "Model folder (with point_cloud.ply) or a .ply file")->required();
       sub.add_option("--out", a->out, "Output folder")->required();
       sub.add_option("--split", a->split, "Views to render")
           ->check(CLI::IsMember({"test", "train", "all"}))
           ->capture_default_str();
       sub.add_option("--downscale", a->downscale, "Integer image downscale factor")
           ->check(CLI::Range(1, 64))
           ->capture_default_str();
       add_threads_option(sub, a->threads);
       auto* w =
           sub.add_flag("--white-bg", a->white_bg, "White background (default: as in MODEL/config.json, else black)");
       sub.add_flag("--black-bg", a->black_bg, "Black background")->excludes(w);
       sub.add_option("--near-plane", a->near_plane,
                      "Cull Gaussians nearer than this to the camera (default: as in MODEL/config.json, else 0.01)")
           ->check(CLI::PositiveNumber);
       sub.add_flag("--quiet", a->quiet, "No progress output");
       return [a] { run_render(*a); };
     }});

}  // namespace
}  // namespace hgs::cli
