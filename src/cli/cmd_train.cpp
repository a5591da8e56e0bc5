// `hgs train SCENE --out MODEL [--method hybrid|rgb]`: Hybrid Gaussians (default) or plain 3DGS training. Writes
// MODEL/point_cloud.ply (3DGS layout), MODEL/config.json, MODEL/train_stats.json and, with --save-every,
// MODEL/checkpoints/iter_<N>.ckpt (+ the final one) for --resume.
#include <omp.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>

#include <algorithm>
#include <atomic>
#include <chrono>

#include "cli/command.h"
#include "cli/held_out_score.h"
#include "core/error.h"
#include "core/fs.h"
#include "core/progress.h"
#include "core/process.h"
#include "mpi/session.h"
#include "model/ply.h"
#include "scene/scene.h"
#include "hybrid/config.h"
#include "hybrid/register.h"
#include "train/registry.h"
#include "train/trainer.h"

namespace hgs::cli {
namespace {

struct TrainArgs {
  std::string scene, out, method = "hybrid", resume;
  hybrid::HybridConfig hybrid;
  bool no_of = false, no_scl = false, no_bro = false;
  std::string batch_lr = "none";
  std::string lang_storage = "half", bro_gradient = "scale-invariant", bro_norm = "image", unconfident = "unobserved";
  int iters = 30000, downscale = 1, threads = 0, sh_degree = 3, save_every = 0, batch = 1, test_every = 0;
  uint64_t seed = 0;
  bool no_densify = false, white_bg = false, quiet = false;
};

void run_train(const TrainArgs& a) {
  // Under mpirun every rank runs this same function on the same scene and configuration; rank 0 alone writes
  // outputs and shows progress (docs/scaling.md).
  mpi::Session mpi;
  const int R = mpi.size(), G = a.batch * R;
  const bool writer = mpi.rank() == 0;
  // Ranks sharing a machine share its cores: by default each takes its share.
  set_threads(a.threads == 0 && R > 1 ? std::max(1, omp_get_num_procs() / mpi::local_ranks()) : a.threads);
  Scene scene = load_scene(a.scene, {a.downscale, false});
  std::vector<int> train_idx = scene.train_indices();
  if (train_idx.empty()) fail("{}: the scene has no training views", a.scene);
  if (G > int(train_idx.size()))
    fail("{}: a step of {} views ({} per rank x {} ranks) is more than the {} training views", a.scene, G, a.batch,
         R, train_idx.size());
  if (a.save_every % G != 0)
    fail("--save-every {} is not a multiple of the {} views of a step (--batch {} x {} ranks)", a.save_every, G,
         a.batch, R);
  const bool progress = !a.quiet && writer;
  const fs::path out = a.out;
  if (writer) ensure_dir(out);

  train::TrainConfig base;
  base.sh_degree = a.sh_degree;
  train::TrainConfig cfg = base.scaled_to(a.iters);
  cfg.method = a.method;
  cfg.seed = a.seed;
  cfg.densify = !a.no_densify;
  cfg.white_bg = a.white_bg;
  cfg.save_every = a.save_every;
  cfg.batch = a.batch;
  cfg.batch_lr = a.batch_lr;

  std::optional<hybrid::HybridConfig> hc;
  if (a.method == "hybrid") {
    hc = a.hybrid;
    hc->use_of = !a.no_of;
    hc->use_scl = !a.no_scl;
    hc->use_bro = !a.no_bro;
    hc->lang_half = a.lang_storage == "half";
    hc->bro_scale_invariant = a.bro_gradient == "scale-invariant";
    hc->bro_image_norm = a.bro_norm == "image";
    hc->unconfident_unobserved = a.unconfident == "unobserved";
  }
  hybrid::register_method();
  auto trainer_ptr = train::make_trainer(scene, train_idx, cfg, a.method, hc ? hc->to_json() : nlohmann::json(),
                                         progress, &mpi.reducer());
  train::Trainer& trainer = *trainer_ptr;
  const int init_points = trainer.model().n;
  if (!a.resume.empty()) {
    trainer.load_checkpoint(a.resume);
    if (trainer.iteration() >= a.iters)
      fail("{}: checkpoint is at iteration {}, nothing to do for --iters {}", a.resume, trainer.iteration(), a.iters);
  }
  if ((a.iters - trainer.iteration()) % G != 0)
    fail("--iters {}: the {} images left after iteration {} are not a multiple of the {} views of a step (--batch "
         "{} x {} ranks)", a.iters, a.iters - trainer.iteration(), trainer.iteration(), G, a.batch, R);

  nlohmann::json config = trainer.config().to_json();
  config["scene"] = fs::absolute(scene.root).lexically_normal().string();
  config["downscale"] = a.downscale;
  config["extent"] = trainer.extent();
  config["train_views"] = train_idx.size();
  config["init_points"] = init_points;
  config["split"] = scene.split_source;
  if (hc) config["hybrid"] = hc->to_json();
  if (!a.resume.empty()) config["resumed_from"] = a.resume;
  config["ranks"] = R;
  if (writer) atomic_write_text(out / "config.json", config.dump(2) + "\n");

  const int start = trainer.iteration();
  std::vector<float> ms;
  ms.reserve(a.iters - start);
  Progress bar("train", a.iters - start, progress);
  double ema_loss = 0, ema_psnr = 0;  // of the optimised total and the training view's PSNR
  std::vector<std::pair<std::string, double>> ema_terms;  // each weighted term, in the objective's order
  train::StepTimes parts;  // summed over the steps of this run
  auto t0 = std::chrono::steady_clock::now();
  // --test-every: the held-out views' PSNR / SSIM every N images seen, against the training time so far (the
  // scoring itself excluded), for curves and time-to-quality figures.
  const std::vector<int> test_idx = a.test_every > 0 && writer ? scene.test_indices() : std::vector<int>{};
  if (a.test_every > 0 && writer && test_idx.empty())
    fail("--test-every: {} has no held-out views (its split puts every view in training)", a.scene);
  std::vector<Image> test_images;
  nlohmann::json test_curve = nlohmann::json::array();
  double test_seconds = 0;  // spent scoring, not training
  std::string last_ckpt = a.resume;  // the newest checkpoint on disk, for the message of a failed step
  // Test hook (tests/mpi): HGS_TEST_KILL=<rank>:<images> kills that rank with SIGKILL once it has seen that many
  // images, as a crashed machine would.
  int kill_at = 0;
  if (const char* k = std::getenv("HGS_TEST_KILL")) {
    int r = -1, at = 0;
    if (std::sscanf(k, "%d:%d", &r, &at) != 2 || r < 0 || at <= 0) fail("HGS_TEST_KILL: expected <rank>:<images>, got '{}'", k);
    if (r == mpi.rank()) kill_at = at;
  }
  while (trainer.iteration() < a.iters) {
    train::StepInfo s;
    try {
      s = trainer.step();
    } catch (const Error& e) {  // e.g. a non-finite loss or gradient: nothing of this run's state is saved
      if (last_ckpt.empty()) fail("{} (no checkpoint was written: --save-every N keeps one)", e.what());
      fail("{} (the last checkpoint {} is intact: --resume from it)", e.what(), last_ckpt);
    }
    ms.push_back(float(s.ms));
    train::StepTimes::each([&](const char*, double train::StepTimes::*m) { parts.*m += s.times.*m; });
    bool first = ms.size() == 1;
    ema_loss = first ? s.total : 0.4 * s.total + 0.6 * ema_loss;
    if (first || ema_terms.size() != s.terms.size()) {
      ema_terms.clear();
      for (const auto& t : s.terms) ema_terms.push_back({t.name, t.weighted()});
    } else {
      for (size_t k = 0; k < s.terms.size(); ++k) ema_terms[k].second = 0.4 * s.terms[k].weighted() + 0.6 * ema_terms[k].second;
    }
    ema_psnr = first ? s.psnr : 0.4 * s.psnr + 0.6 * ema_psnr;
    const int it = trainer.iteration();
    if (kill_at > 0 && it >= kill_at) std::raise(SIGKILL);
    if (!test_idx.empty() && (it / a.test_every > (it - G) / a.test_every || it >= a.iters)) {
      const auto ts = std::chrono::steady_clock::now();
      const ViewScore sc = score_views(scene, test_idx, trainer.model(), a.white_bg, test_images);
      const double train_s = std::chrono::duration<double>(ts - t0).count() - test_seconds;
      test_seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
      test_curve.push_back({{"iteration", it}, {"train_seconds", train_s}, {"test_psnr", sc.psnr}, {"test_ssim", sc.ssim},
                            {"num_gaussians", trainer.model().n}});
      bar.note(fmt::format("test {:>7}: PSNR {:.2f} dB, SSIM {:.4f} ({} views) after {} of training", it, sc.psnr,
                           sc.ssim, test_idx.size(), format_duration(train_s)));
    }
    if (writer && a.save_every > 0 && it % a.save_every == 0 && it < a.iters) {
      ensure_dir(out / "checkpoints");
      trainer.save_checkpoint(out / "checkpoints" / fmt::format("iter_{}.ckpt", it));
      write_model_ply(out / fmt::format("point_cloud_iter_{}.ply", it), trainer.model());
      last_ckpt = (out / "checkpoints" / fmt::format("iter_{}.ckpt", it)).string();
    }
    if (progress) {
      std::string terms;
      if (ema_terms.size() > 1)
        for (const auto& [name, v] : ema_terms) terms += fmt::format("{}{} {:.4f}", terms.empty() ? " (" : " ", name, v);
      if (!terms.empty()) terms += ")";
      bar.update(it - start, fmt::format("loss {:.4f}{} psnr {:.2f} N {} {:.1f} ms/it", ema_loss, terms, ema_psnr,
                                         s.num_gaussians, s.ms));
    }
  }
  double wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  bar.finish(fmt::format("loss {:.4f} psnr {:.2f} N {}", ema_loss, ema_psnr, trainer.model().n));
  if (!writer) return;  // every rank holds the same model; rank 0 writes it
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
                          {"mean_ms_per_iter", ms.empty() ? 0.0 : (wall - test_seconds) * 1000.0 / ms.size()},
                          {"peak_rss_mb", peak_rss_mb()},
                          {"num_gaussians", trainer.model().n},
                          {"wall_time_s", wall},
                          {"test_seconds", test_seconds},  // of wall_time_s, spent on --test-every
                          {"test_curve", test_curve},
                          {"final_train_loss_ema", ema_loss},
                          {"final_train_loss_terms_ema", [&] {
                             nlohmann::json j = nlohmann::json::object();  // weighted: they sum to the total
                             for (const auto& [name, v] : ema_terms) j[name] = v;
                             return j;
                           }()},
                          {"final_train_psnr_ema", ema_psnr},
                          {"threads", omp_get_max_threads()},
                          {"ranks", R},
                          {"views_per_step", G},
                          // this rank's share of the gradient exchange (rank 0; every rank sends about as much)
                          {"comm_bytes_per_step", ms.empty() ? 0.0 : trainer.reducer().stats.bytes_sent / ms.size()},
                          {"comm_ms_per_step", ms.empty() ? 0.0 : trainer.reducer().stats.ms / ms.size()}};
  nlohmann::json part_ms = nlohmann::json::object();
  std::string part_line;
  train::StepTimes::each([&](const char* name, double train::StepTimes::*m) {
    const double v = ms.empty() ? 0.0 : parts.*m / ms.size();
    part_ms[name] = v;
    part_line += fmt::format("{}{} {:.1f}", part_line.empty() ? "" : ", ", name, v);
  });
  stats["mean_ms_per_part"] = part_ms;
  atomic_write_text(out / "train_stats.json", stats.dump(2) + "\n");
  if (progress)
    fmt::print("trained {} iterations in {} ({:.1f} ms/it median), {} Gaussians -> {}\n", trainer.iteration() - start,
               format_duration(wall), stats["median_ms_per_iter"].get<double>(), trainer.model().n,
               (out / "point_cloud.ply").string());
  if (progress) fmt::print("mean ms per step: {}\n", part_line);
  if (progress && R > 1)
    fmt::print("gradient exchange per step (rank 0): {:.2f} MB sent, {:.1f} ms\n",
               stats["comm_bytes_per_step"].get<double>() / 1e6, stats["comm_ms_per_step"].get<double>());
}

CommandRegistration reg({"train", "Optimise Hybrid Gaussians (or plain 3DGS with --method rgb) on a scene's training views", 20, [](CLI::App& sub) {
  auto a = std::make_shared<TrainArgs>();
  sub.add_option("SCENE", a->scene, "Scene folder (images/, sparse/0/, ...)")->required();
  sub.add_option("--out", a->out, "Output model folder")->required();
  sub.add_option("--method", a->method, "hybrid (Hybrid Gaussians: objects + language) or rgb (plain 3DGS)")
      ->check(CLI::IsMember({"hybrid", "rgb"}))->capture_default_str();
  auto& h = a->hybrid;
  sub.add_flag("--no-of", a->no_of, "Ablation: single-view hard association instead of Observation Fusion");
  sub.add_flag("--no-scl", a->no_scl, "Ablation: per-pixel cosine semantic loss instead of Semantic Contrastive Learning");
  sub.add_flag("--no-bro", a->no_bro, "Ablation: no Boundary Reconstruction Optimization (lambda_bro = 0)");
  sub.add_option("--lambda-rgb", h.lambda_rgb, "Weight of the full-image photometric loss (0 = eq. 15 alone)")->capture_default_str();
  sub.add_option("--lambda-app", h.lambda_app, "Weight of the object-conditioned appearance loss (eq. 6)")->capture_default_str();
  sub.add_option("--lambda-sem", h.lambda_sem, "Weight of the semantic loss (eq. 10)")->capture_default_str();
  sub.add_option("--lambda-bro", h.lambda_bro, "Weight of the boundary loss (eq. 14)")->capture_default_str();
  sub.add_option("--tau1", h.tau1, "Mask confidence threshold (eq. 2)")->capture_default_str();
  sub.add_option("--fusion-temperature", h.temperature, "Temperature T of the association softmax (eq. 5)")->capture_default_str();
  sub.add_option("--tau2", h.tau2, "InfoNCE temperature (eq. 10)")->capture_default_str();
  sub.add_option("--scl-background", h.scl_background,
                 "The background as a Semantic Contrastive Learning class: auto (in views with fewer than two "
                 "foreground objects, where eq. 10 has no negative), on (every view) or off (eq. 10 as written); "
                 "see hybrid/config.h")
      ->check(CLI::IsMember({"auto", "on", "off"}))->capture_default_str();
  sub.add_option("--fusion-every", h.fusion_every, "Rebuild the observation table every R iterations")->capture_default_str();
  sub.add_option("--objects-per-step", h.objects_per_step,
                 "Approximation for speed: score M randomly drawn objects of each view per step in eqs. 6 and 14 "
                 "(an unbiased estimate; 0 = every object, exact; see hybrid/config.h)")
      ->check(CLI::Range(0, 65535))->capture_default_str();
  sub.add_option("--bro-kernel", h.bro_kernel, "Side of the square structuring element of BRO")->check(CLI::Range(1, 63))->capture_default_str();
  sub.add_option("--unconfident", a->unconfident,
                 "What a mask pixel below --tau1 tells Observation Fusion: unobserved (nothing; see hybrid/fusion.h) "
                 "or background (eq. 2 as written)")
      ->check(CLI::IsMember({"unobserved", "background"}))->capture_default_str();
  sub.add_option("--background-vote", h.background_vote,
                 "Weight of a background observation in Observation Fusion's evidence (eq. 4; 1 = the paper; see "
                 "hybrid/fusion.h)")->check(CLI::Range(0.0, 1.0))->capture_default_str();
  sub.add_flag("--occlusion-test,!--no-occlusion-test", h.occlusion_test,
               "Observation Fusion counts a view only where the Gaussian is not hidden behind the surface the "
               "model renders there (on by default; one extra render per view at each table rebuild; see "
               "hybrid/fusion.h). --no-occlusion-test = eq. 3's V");
  sub.add_option("--bro-gradient", a->bro_gradient,
                 "scale-invariant (BRO cannot fade a whole object; see hybrid/bro.h) or plain (eq. 14's own gradient)")
      ->check(CLI::IsMember({"scale-invariant", "plain"}))->capture_default_str();
  sub.add_option("--bro-norm", a->bro_norm,
                 "image (eq. 14 weighted by its band's share of the image, like eq. 6; see hybrid/bro.h) or band "
                 "(eq. 14 as written)")
      ->check(CLI::IsMember({"image", "band"}))->capture_default_str();
  sub.add_flag("--sem-geometry", h.sem_geometry,
               "Let the semantic loss (eq. 10) move opacities and geometry too (default: it trains f and q only)");
  sub.add_option("--lr-lang", h.lr_lang, "Adam learning rate of the language embeddings")->capture_default_str();
  sub.add_option("--lang-storage", a->lang_storage,
                 "Language embeddings in half precision with bfloat16 Adam moments (half), or all float32 (f32)")
      ->check(CLI::IsMember({"half", "f32"}))->capture_default_str();
  sub.add_option("--lr-view", h.lr_view, "Adam learning rate of the view reliability logits")->capture_default_str();
  sub.add_option("--batch", a->batch,
                 "Views per step on this process: their gradients are averaged (learning rates unchanged); under "
                 "mpirun each of R ranks takes this many, R x B per step (docs/scaling.md)")
      ->check(CLI::Range(1, 4096))->capture_default_str();
  sub.add_option("--iters", a->iters, "Training images to see (steps x views per step); the 30k densification schedule is scaled to this")
      ->check(CLI::Range(1, 10000000))->capture_default_str();
  sub.add_option("--downscale", a->downscale, "Integer image downscale factor")->check(CLI::Range(1, 64))->capture_default_str();
  sub.add_option("--threads", a->threads, "Worker threads (0 = all cores)")->check(CLI::Range(0, 1024));
  sub.add_option("--seed", a->seed, "Random seed (view order, split sampling)")->capture_default_str();
  sub.add_option("--sh-degree", a->sh_degree, "Maximum SH degree")->check(CLI::Range(0, 3))->capture_default_str();
  sub.add_option("--batch-lr", a->batch_lr,
                 "Learning-rate rule for several views per step (--batch x ranks = G): none (rates and Adam betas "
                 "as at one view), sqrt (rates x sqrt(G), betas^G, as Grendel) or sqrt-rates (rates x sqrt(G) only); see "
                 "train/config.h")
      ->check(CLI::IsMember({"none", "sqrt", "sqrt-rates"}))->capture_default_str();
  sub.add_option("--test-every", a->test_every,
                 "Score the held-out views (PSNR, SSIM) every N images seen and at the end; the curve, with the "
                 "training time to each point, goes to train_stats.json (0 = off)")
      ->check(CLI::Range(0, 10000000))->capture_default_str();
  sub.add_option("--save-every", a->save_every, "Write a checkpoint and a PLY every N iterations (0 = off; a multiple of the views per step)")
      ->check(CLI::Range(0, 10000000))->capture_default_str();
  sub.add_option("--resume", a->resume, "Continue from a checkpoint (MODEL/checkpoints/iter_N.ckpt)");
  sub.add_flag("--no-densify", a->no_densify, "Keep the Gaussian count fixed (no clone/split/prune/opacity reset)");
  sub.add_flag("--white-bg", a->white_bg, "White background (default black)");
  sub.add_flag("--quiet", a->quiet, "No progress output");
  return [a] { run_train(*a); };
}});

}  // namespace
}  // namespace hgs::cli
