// `hgs train SCENE --out MODEL --method rgb`: 3DGS training on a scene's training views. Writes
// MODEL/point_cloud.ply (3DGS layout), MODEL/config.json, MODEL/train_stats.json and, with --save-every,
// MODEL/checkpoints/iter_<N>.ckpt (+ the final one) for --resume.
#include <omp.h>
#include <sys/resource.h>

#include <algorithm>
#include <atomic>
#include <chrono>

#include "cli/command.h"
#include "core/error.h"
#include "core/fs.h"
#include "core/progress.h"
#include "model/ply.h"
#include "scene/scene.h"
#include "train/trainer.h"

namespace hgs::cli {
namespace {

struct TrainArgs {
  std::string scene, out, method = "rgb", resume;
  int iters = 30000, downscale = 1, threads = 0, sh_degree = 3, save_every = 0;
  uint64_t seed = 0;
  bool no_densify = false, white_bg = false, quiet = false;
};

double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / 1024.0;  // ru_maxrss is in KiB on Linux
}

// Loads the training images (downscaled by the scene) in parallel.
std::vector<train::TrainView> load_views(const Scene& scene, const std::vector<int>& idx, bool progress) {
  std::vector<train::TrainView> views(idx.size());
  Progress bar("load", long(idx.size()), progress);
  std::atomic<long> done{0};
  std::string error;
#pragma omp parallel for schedule(dynamic)
  for (size_t i = 0; i < idx.size(); ++i) {
    try {
      const View& v = scene.views[idx[i]];
      views[i].name = v.name;
      views[i].cam = train::make_camera(v);
      views[i].image = scene.load_image(idx[i]);
    } catch (const std::exception& e) {
#pragma omp critical
      if (error.empty()) error = e.what();
    }
    long d = ++done;
    if (omp_get_thread_num() == 0) bar.update(d);
  }
  if (!error.empty()) throw Error(error);
  bar.finish();
  return views;
}

void run_train(const TrainArgs& a) {
  set_threads(a.threads);
  if (a.method != "rgb") fail("--method {}: only 'rgb' is implemented by hgs train so far", a.method);
  Scene scene = load_scene(a.scene, {a.downscale, false});
  std::vector<int> train_idx = scene.train_indices();
  if (train_idx.empty()) fail("{}: the scene has no training views", a.scene);
  const bool progress = !a.quiet;
  const fs::path out = a.out;
  ensure_dir(out);

  train::TrainConfig base;
  base.sh_degree = a.sh_degree;
  train::TrainConfig cfg = base.scaled_to(a.iters);
  cfg.method = a.method;
  cfg.seed = a.seed;
  cfg.densify = !a.no_densify;
  cfg.white_bg = a.white_bg;
  cfg.save_every = a.save_every;

  auto views = load_views(scene, train_idx, progress);
  const float extent = scene_extent(scene, train_idx);
  GaussianModel init = init_from_points(scene.points, scene.point_colors, a.sh_degree);
  const int init_points = init.n;
  train::Trainer trainer(cfg, std::move(init), std::move(views), extent);
  if (!a.resume.empty()) {
    trainer.load_checkpoint(a.resume);
    if (trainer.iteration() >= a.iters)
      fail("{}: checkpoint is at iteration {}, nothing to do for --iters {}", a.resume, trainer.iteration(), a.iters);
  }

  nlohmann::json config = trainer.config().to_json();
  config["scene"] = fs::absolute(scene.root).lexically_normal().string();
  config["downscale"] = a.downscale;
  config["extent"] = trainer.extent();
  config["train_views"] = train_idx.size();
  config["init_points"] = init_points;
  config["split"] = scene.split_source;
  if (!a.resume.empty()) config["resumed_from"] = a.resume;
  atomic_write_text(out / "config.json", config.dump(2) + "\n");

  const int start = trainer.iteration();
  std::vector<float> ms;
  ms.reserve(a.iters - start);
  Progress bar("train", a.iters - start, progress);
  double ema_loss = 0, ema_psnr = 0;
  auto t0 = std::chrono::steady_clock::now();
  while (trainer.iteration() < a.iters) {
    train::StepInfo s = trainer.step();
    ms.push_back(float(s.ms));
    bool first = ms.size() == 1;
    ema_loss = first ? s.loss.total : 0.4 * s.loss.total + 0.6 * ema_loss;
    ema_psnr = first ? s.psnr : 0.4 * s.psnr + 0.6 * ema_psnr;
    const int it = trainer.iteration();
    if (a.save_every > 0 && it % a.save_every == 0 && it < a.iters) {
      ensure_dir(out / "checkpoints");
      trainer.save_checkpoint(out / "checkpoints" / fmt::format("iter_{}.ckpt", it));
      write_model_ply(out / fmt::format("point_cloud_iter_{}.ply", it), trainer.model());
    }
    if (progress)
      bar.update(it - start, fmt::format("loss {:.4f} psnr {:.2f} N {} {:.1f} ms/it", ema_loss, ema_psnr,
                                         s.num_gaussians, s.ms));
  }
  double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  bar.finish(fmt::format("loss {:.4f} psnr {:.2f} N {}", ema_loss, ema_psnr, trainer.model().n));
  write_model_ply(out / "point_cloud.ply", trainer.model());
  if (a.save_every > 0) {
    ensure_dir(out / "checkpoints");
    trainer.save_checkpoint(out / "checkpoints" / fmt::format("iter_{}.ckpt", trainer.iteration()));
  }
  std::vector<float> sorted = ms;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  nlohmann::json stats = {{"iterations", trainer.iteration()},
                          {"iterations_this_run", trainer.iteration() - start},
                          {"median_ms_per_iter", sorted.empty() ? 0.0 : sorted[sorted.size() / 2]},
                          {"mean_ms_per_iter", ms.empty() ? 0.0 : wall * 1000.0 / ms.size()},
                          {"peak_rss_mb", peak_rss_mb()},
                          {"num_gaussians", trainer.model().n},
                          {"wall_time_s", wall},
                          {"final_train_loss_ema", ema_loss},
                          {"final_train_psnr_ema", ema_psnr},
                          {"threads", omp_get_max_threads()}};
  atomic_write_text(out / "train_stats.json", stats.dump(2) + "\n");
  if (progress)
    fmt::print("trained {} iterations in {} ({:.1f} ms/it median), {} Gaussians -> {}\n", trainer.iteration() - start,
               format_duration(wall), stats["median_ms_per_iter"].get<double>(), trainer.model().n,
               (out / "point_cloud.ply").string());
}

CommandRegistration reg({"train", "Optimise Gaussians on a scene's training views (3DGS RGB training)", 20, [](CLI::App& sub) {
  auto a = std::make_shared<TrainArgs>();
  sub.add_option("SCENE", a->scene, "Scene folder (images/, sparse/0/, ...)")->required();
  sub.add_option("--out", a->out, "Output model folder")->required();
  sub.add_option("--method", a->method, "Training method (rgb = plain 3DGS)")->capture_default_str();
  sub.add_option("--iters", a->iters, "Iterations (the 30k densification schedule is scaled to this)")
      ->check(CLI::Range(1, 10000000))->capture_default_str();
  sub.add_option("--downscale", a->downscale, "Integer image downscale factor")->check(CLI::Range(1, 64))->capture_default_str();
  sub.add_option("--threads", a->threads, "Worker threads (0 = all cores)")->check(CLI::Range(0, 1024));
  sub.add_option("--seed", a->seed, "Random seed (view order, split sampling)")->capture_default_str();
  sub.add_option("--sh-degree", a->sh_degree, "Maximum SH degree")->check(CLI::Range(0, 3))->capture_default_str();
  sub.add_option("--save-every", a->save_every, "Write a checkpoint and a PLY every N iterations (0 = off)")
      ->check(CLI::Range(0, 10000000))->capture_default_str();
  sub.add_option("--resume", a->resume, "Continue from a checkpoint (MODEL/checkpoints/iter_N.ckpt)");
  sub.add_flag("--no-densify", a->no_densify, "Keep the Gaussian count fixed (no clone/split/prune/opacity reset)");
  sub.add_flag("--white-bg", a->white_bg, "White background (default black)");
  sub.add_flag("--quiet", a->quiet, "No progress output");
  return [a] { run_train(*a); };
}});

}  // namespace
}  // namespace hgs::cli
