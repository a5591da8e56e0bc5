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
#include <optional>
#include <string>
#include <vector>

#include "cli/command.h"
#include "cli/held_out_score.h"
#include "core/error.h"
#include "core/fs.h"
#include "core/process.h"
#include "core/progress.h"
#include "hybrid/config.h"
#include "hybrid/register.h"
#include "model/ply.h"
#include "mpi/session.h"
#include "scene/scene.h"
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
  float near_plane = render::kDefaultNearPlane;
  float late_prune = 0.f;
  bool no_densify = false, white_bg = false, quiet = false;
};

// The training configuration of the command line: the 30k schedule scaled to --iters.
train::TrainConfig train_config(const TrainArgs& a) {
  train::TrainConfig base;
  base.sh_degree = a.sh_degree;
  train::TrainConfig cfg = base.scaled_to(a.iters);
  cfg.method = a.method;
  cfg.seed = a.seed;
  cfg.densify = !a.no_densify;
  cfg.white_bg = a.white_bg;
  cfg.near_plane = a.near_plane;
  cfg.late_prune = a.late_prune;
  cfg.save_every = a.save_every;
  cfg.batch = a.batch;
  cfg.batch_lr = a.batch_lr;
  return cfg;
}

// The hybrid method's options (none for --method rgb).
std::optional<hybrid::HybridConfig> hybrid_config(const TrainArgs& a) {
  if (a.method != "hybrid") return std::nullopt;
  hybrid::HybridConfig hc = a.hybrid;
  hc.use_of = !a.no_of;
  hc.use_scl = !a.no_scl;
  hc.use_bro = !a.no_bro;
  hc.lang_half = a.lang_storage == "half";
  hc.bro_scale_invariant = a.bro_gradient == "scale-invariant";
  hc.bro_image_norm = a.bro_norm == "image";
  hc.unconfident_unobserved = a.unconfident == "unobserved";
  return hc;
}

// A step of G = --batch x ranks views must fit the training views, and --save-every whole steps.
void check_step_size(const TrainArgs& a, size_t train_views, int ranks) {
  const int G = a.batch * ranks;
  if (G > int(train_views))
    fail("{}: a step of {} views ({} per rank x {} ranks) is more than the {} training views", a.scene, G, a.batch,
         ranks, train_views);
  if (a.save_every % G != 0)
    fail("--save-every {} is not a multiple of the {} views of a step (--batch {} x {} ranks)", a.save_every, G,
         a.batch, ranks);
}

// MODEL/config.json: the run's configuration and where it came from.
nlohmann::json run_config(const TrainArgs& a, const Scene& scene, const train::Trainer& trainer, size_t train_views,
                          int init_points, const std::optional<hybrid::HybridConfig>& hc, int ranks) {
  nlohmann::json config = trainer.config().to_json();
  config["scene"] = fs::absolute(scene.root).lexically_normal().string();
  config["downscale"] = a.downscale;
  config["extent"] = trainer.extent();
  config["train_views"] = train_views;
  config["init_points"] = init_points;
  config["split"] = scene.split_source;
  if (hc) config["hybrid"] = hc->to_json();
  if (!a.resume.empty()) config["resumed_from"] = a.resume;
  config["ranks"] = ranks;
  return config;
}

// Exponential moving averages of the optimised total, each weighted term (in the objective's order) and the
// training views' PSNR: the progress line and train_stats.json.
struct LossEma {
  double loss = 0, psnr = 0;
  std::vector<std::pair<std::string, double>> terms;
  void add(const train::StepInfo& s, bool first) {
    loss = first ? s.total : 0.4 * s.total + 0.6 * loss;
    if (first || terms.size() != s.terms.size()) {
      terms.clear();
      for (const auto& t : s.terms) terms.push_back({t.name, t.weighted()});
    } else {
      for (size_t k = 0; k < s.terms.size(); ++k) terms[k].second = 0.4 * s.terms[k].weighted() + 0.6 * terms[k].second;
    }
    psnr = first ? s.psnr : 0.4 * s.psnr + 0.6 * psnr;
  }
  // " (rgb 0.1234 app 0.0100 ...)" when there is more than one term.
  std::string terms_text() const {
    std::string t;
    if (terms.size() > 1)
      for (const auto& [name, v] : terms) t += fmt::format("{}{} {:.4f}", t.empty() ? " (" : " ", name, v);
    return t.empty() ? t : t + ")";
  }
  nlohmann::json terms_json() const {
    nlohmann::json j = nlohmann::json::object();  // weighted: they sum to the total
    for (const auto& [name, v] : terms) j[name] = v;
    return j;
  }
};

// --test-every: the held-out views' PSNR / SSIM every N images seen and at the end, against the training time so
// far (the scoring itself excluded), for curves and time-to-quality figures.
class HeldOutCurve {
 public:
  HeldOutCurve(const TrainArgs& a, const Scene& scene, bool writer, float near_plane)
      : every_(a.test_every), last_(a.iters), white_(a.white_bg), near_(near_plane) {
    if (every_ <= 0 || !writer) return;
    views_ = scene.test_indices();
    if (views_.empty()) fail("--test-every: {} has no held-out views (its split puts every view in training)", a.scene);
  }
  // After a step that ended at `it` images seen (G of them in this step).
  void after_step(int it, int G, const Scene& scene, const train::Trainer& trainer, Progress& bar,
                  std::chrono::steady_clock::time_point t0) {
    if (views_.empty() || !(it / every_ > (it - G) / every_ || it >= last_)) return;
    const auto ts = std::chrono::steady_clock::now();
    const ViewScore sc = score_views(scene, views_, trainer.model(), white_, near_, images_);
    const double train_s = std::chrono::duration<double>(ts - t0).count() - seconds_;
    seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
    curve_.push_back({{"iteration", it},
                      {"train_seconds", train_s},
                      {"test_psnr", sc.psnr},
                      {"test_ssim", sc.ssim},
                      {"num_gaussians", trainer.model().n}});
    bar.note(fmt::format("test {:>7}: PSNR {:.2f} dB, SSIM {:.4f} ({} views) after {} of training", it, sc.psnr,
                         sc.ssim, views_.size(), format_duration(train_s)));
  }
  const nlohmann::json& curve() const { return curve_; }
  double seconds() const { return seconds_; }  // spent scoring, not training

 private:
  int every_, last_;
  bool white_;
  float near_;
  std::vector<int> views_;
  std::vector<Image> images_;
  nlohmann::json curve_ = nlohmann::json::array();
  double seconds_ = 0;
};

// Test hook (tests/mpi): HGS_TEST_KILL=<rank>:<images> kills that rank with SIGKILL once it has seen that many
// images, as a crashed machine would. Returns the images for this rank (0 = never).
int kill_hook(int rank) {
  const char* k = std::getenv("HGS_TEST_KILL");
  if (!k) return 0;
  int r = -1, at = 0;
  if (std::sscanf(k, "%d:%d", &r, &at) != 2 || r < 0 || at <= 0)
    fail("HGS_TEST_KILL: expected <rank>:<images>, got '{}'", k);
  return r == rank ? at : 0;
}

// MODEL/checkpoints/iter_<it>.ckpt (and, during training, MODEL/point_cloud_iter_<it>.ply). Returns the checkpoint.
std::string save_snapshot(const fs::path& out, const train::Trainer& trainer, bool with_ply) {
  const int it = trainer.iteration();
  ensure_dir(out / "checkpoints");
  const fs::path ckpt = out / "checkpoints" / fmt::format("iter_{}.ckpt", it);
  trainer.save_checkpoint(ckpt);
  if (with_ply) write_model_ply(out / fmt::format("point_cloud_iter_{}.ply", it), trainer.model());
  return ckpt.string();
}

// What one run measured, for train_stats.json and the closing lines.
struct RunTimes {
  std::vector<float> ms;          // wall ms of each step of this run
  std::vector<int> iter;          // the iteration (images seen) each step ended at
  std::vector<float> densify_ms;  // ... and its densification / opacity reset / after_step part
  train::StepTimes parts;         // summed over the steps
  double wall = 0;                // seconds, test scoring included
};

nlohmann::json train_stats(const train::Trainer& trainer, int start, const RunTimes& rt, const LossEma& ema,
                           const HeldOutCurve& held_out, int ranks, int G) {
  const std::vector<float>& ms = rt.ms;
  std::vector<float> sorted = ms;
  std::nth_element(sorted.begin(), sorted.begin() + sorted.size() / 2, sorted.end());
  nlohmann::json stats = {{"iterations", trainer.iteration()},
                          {"iterations_this_run", trainer.iteration() - start},
                          {"median_ms_per_iter", sorted.empty() ? 0.0 : sorted[sorted.size() / 2]},
                          {"mean_ms_per_iter", ms.empty() ? 0.0 : (rt.wall - held_out.seconds()) * 1000.0 / ms.size()},
                          {"peak_rss_mb", peak_rss_mb()},
                          {"num_gaussians", trainer.model().n},
                          {"wall_time_s", rt.wall},
                          {"test_seconds", held_out.seconds()},  // of wall_time_s, spent on --test-every
                          {"test_curve", held_out.curve()},
                          {"final_train_loss_ema", ema.loss},
                          {"final_train_loss_terms_ema", ema.terms_json()},
                          {"final_train_psnr_ema", ema.psnr},
                          {"threads", omp_get_max_threads()},
                          {"ranks", ranks},
                          {"views_per_step", G},
                          // this rank's share of the gradient exchange (rank 0; every rank sends about as much)
                          {"comm_bytes_per_step", ms.empty() ? 0.0 : trainer.reducer().stats.bytes_sent / ms.size()},
                          {"comm_ms_per_step", ms.empty() ? 0.0 : trainer.reducer().stats.ms / ms.size()}};
  // The slowest steps (where the mean departs from the median: densification, observation-table rebuilds).
  std::vector<size_t> order(ms.size());
  for (size_t i = 0; i < order.size(); ++i) order[i] = i;
  const size_t top = std::min<size_t>(5, order.size());
  std::partial_sort(order.begin(), order.begin() + top, order.end(), [&](size_t x, size_t y) { return ms[x] > ms[y]; });
  nlohmann::json slowest = nlohmann::json::array();
  for (size_t i = 0; i < top; ++i)
    slowest.push_back(
        {{"iteration", rt.iter[order[i]]}, {"ms", ms[order[i]]}, {"densify_ms", rt.densify_ms[order[i]]}});
  stats["slowest_steps"] = slowest;
  nlohmann::json part_ms = nlohmann::json::object();
  train::StepTimes::each([&](const char* name, double train::StepTimes::*m) {
    part_ms[name] = ms.empty() ? 0.0 : rt.parts.*m / ms.size();
  });
  stats["mean_ms_per_part"] = part_ms;
  return stats;
}

void print_summary(const nlohmann::json& stats, const fs::path& ply, int ranks) {
  fmt::print("trained {} iterations in {} ({:.1f} ms/it median), {} Gaussians -> {}\n",
             stats["iterations_this_run"].get<int>(), format_duration(stats["wall_time_s"].get<double>()),
             stats["median_ms_per_iter"].get<double>(), stats["num_gaussians"].get<int>(), ply.string());
  std::string part_line;  // in step order
  train::StepTimes::each([&](const char* name, double train::StepTimes::*) {
    part_line +=
        fmt::format("{}{} {:.1f}", part_line.empty() ? "" : ", ", name, stats["mean_ms_per_part"][name].get<double>());
  });
  fmt::print("mean ms per step: {}\n", part_line);
  if (ranks > 1)
    fmt::print("gradient exchange per step (rank 0): {:.2f} MB sent, {:.1f} ms\n",
               stats["comm_bytes_per_step"].get<double>() / 1e6, stats["comm_ms_per_step"].get<double>());
}

// The training loop of one run: steps until --iters, with progress, held-out scores and checkpoints.
void train_loop(const TrainArgs& a, const Scene& scene, train::Trainer& trainer, int rank, bool writer, bool progress,
                RunTimes& rt, LossEma& ema, HeldOutCurve& held_out) {
  const fs::path out = a.out;
  const int start = trainer.iteration(), G = trainer.step_views(), kill_at = kill_hook(rank);
  rt.ms.reserve(a.iters - start);
  Progress bar("train", a.iters - start, progress);
  const auto t0 = std::chrono::steady_clock::now();
  std::string last_ckpt = a.resume;  // the newest checkpoint on disk, for the message of a failed step
  while (trainer.iteration() < a.iters) {
    train::StepInfo s;
    try {
      s = trainer.step();
    } catch (const Error& e) {  // e.g. a non-finite loss or gradient: nothing of this run's state is saved
      if (last_ckpt.empty()) fail("{} (no checkpoint was written: --save-every N keeps one)", e.what());
      fail("{} (the last checkpoint {} is intact: --resume from it)", e.what(), last_ckpt);
    }
    rt.ms.push_back(float(s.ms));
    rt.iter.push_back(trainer.iteration());
    rt.densify_ms.push_back(float(s.times.densify));
    train::StepTimes::each([&](const char*, double train::StepTimes::*m) { rt.parts.*m += s.times.*m; });
    ema.add(s, rt.ms.size() == 1);
    const int it = trainer.iteration();
    if (kill_at > 0 && it >= kill_at) std::raise(SIGKILL);
    held_out.after_step(it, G, scene, trainer, bar, t0);
    if (writer && a.save_every > 0 && it % a.save_every == 0 && it < a.iters)
      last_ckpt = save_snapshot(out, trainer, true);
    if (progress)
      bar.update(it - start, fmt::format("loss {:.4f}{} psnr {:.2f} N {} {:.1f} ms/it", ema.loss, ema.terms_text(),
                                         ema.psnr, s.num_gaussians, s.ms));
  }
  rt.wall = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  bar.finish(fmt::format("loss {:.4f} psnr {:.2f} N {}", ema.loss, ema.psnr, trainer.model().n));
}

void run_train(const TrainArgs& a) {
  // Under mpirun every rank runs this same function on the same scene and configuration; rank 0 alone writes
  // outputs and shows progress (docs/scaling.md).
  mpi::Session mpi;
  const int R = mpi.size(), G = a.batch * R;
  const bool writer = mpi.rank() == 0, progress = !a.quiet && writer;
  // Ranks sharing a machine share its cores: by default each takes its share.
  set_threads(a.threads == 0 && R > 1 ? std::max(1, omp_get_num_procs() / mpi::local_ranks()) : a.threads);
  Scene scene = load_scene(a.scene, {a.downscale, false});
  const std::vector<int> train_idx = scene.train_indices();
  if (train_idx.empty()) fail("{}: the scene has no training views", a.scene);
  check_step_size(a, train_idx.size(), R);
  const fs::path out = a.out;
  if (writer) ensure_dir(out);

  const std::optional<hybrid::HybridConfig> hc = hybrid_config(a);
  hybrid::register_method();
  auto trainer_ptr = train::make_trainer(scene, train_idx, train_config(a), a.method,
                                         hc ? hc->to_json() : nlohmann::json(), progress, &mpi.reducer());
  train::Trainer& trainer = *trainer_ptr;
  const int init_points = trainer.model().n;
  if (!a.resume.empty()) {
    trainer.load_checkpoint(a.resume);
    if (trainer.iteration() >= a.iters)
      fail("{}: checkpoint is at iteration {}, nothing to do for --iters {}", a.resume, trainer.iteration(), a.iters);
  }
  if ((a.iters - trainer.iteration()) % G != 0)
    fail(
        "--iters {}: the {} images left after iteration {} are not a multiple of the {} views of a step (--batch "
        "{} x {} ranks)",
        a.iters, a.iters - trainer.iteration(), trainer.iteration(), G, a.batch, R);
  if (writer)
    atomic_write_text(out / "config.json",
                      run_config(a, scene, trainer, train_idx.size(), init_points, hc, R).dump(2) + "\n");

  const int start = trainer.iteration();
  RunTimes rt;
  LossEma ema;
  HeldOutCurve held_out(a, scene, writer, trainer.config().near_plane);  // a resumed run's, as trained
  train_loop(a, scene, trainer, mpi.rank(), writer, progress, rt, ema, held_out);
  if (!writer) return;  // every rank holds the same model; rank 0 writes it
  write_model_ply(out / "point_cloud.ply", trainer.model());
  if (a.save_every > 0) save_snapshot(out, trainer, false);
  const nlohmann::json stats = train_stats(trainer, start, rt, ema, held_out, R, G);
  atomic_write_text(out / "train_stats.json", stats.dump(2) + "\n");
  if (progress) print_summary(stats, out / "point_cloud.ply", R);
}

// The hybrid method's options (paper components, weights, ablations, approximations).
void add_hybrid_options(CLI::App& sub, TrainArgs& a) {
  auto& h = a.hybrid;
  sub.add_flag("--no-of", a.no_of, "Ablation: single-view hard association instead of Observation Fusion");
  sub.add_flag("--no-scl", a.no_scl,
               "Ablation: per-pixel cosine semantic loss instead of Semantic Contrastive Learning");
  sub.add_flag("--no-bro", a.no_bro, "Ablation: no Boundary Reconstruction Optimization (lambda_bro = 0)");
  sub.add_option("--lambda-rgb", h.lambda_rgb, "Weight of the full-image photometric loss (0 = eq. 15 alone)")
      ->capture_default_str();
  sub.add_option("--lambda-app", h.lambda_app, "Weight of the object-conditioned appearance loss (eq. 6)")
      ->capture_default_str();
  sub.add_option("--lambda-sem", h.lambda_sem, "Weight of the semantic loss (eq. 10)")->capture_default_str();
  sub.add_option("--lambda-bro", h.lambda_bro, "Weight of the boundary loss (eq. 14)")->capture_default_str();
  sub.add_option("--tau1", h.tau1, "Mask confidence threshold (eq. 2)")->capture_default_str();
  sub.add_option("--fusion-temperature", h.temperature, "Temperature T of the association softmax (eq. 5)")
      ->capture_default_str();
  sub.add_option("--tau2", h.tau2, "InfoNCE temperature (eq. 10)")->capture_default_str();
  sub.add_option("--scl-background", h.scl_background,
                 "The background as a Semantic Contrastive Learning class: auto (in views with fewer than two "
                 "foreground objects, where eq. 10 has no negative), on (every view) or off (eq. 10 as written); "
                 "see hybrid/config.h")
      ->check(CLI::IsMember({"auto", "on", "off"}))
      ->capture_default_str();
  sub.add_option("--fusion-every", h.fusion_every, "Rebuild the observation table every R iterations")
      ->capture_default_str();
  sub.add_option("--objects-per-step", h.objects_per_step,
                 "Approximation for speed: score M randomly drawn objects of each view per step in eqs. 6 and 14 "
                 "(an unbiased estimate; 0 = every object, exact; see hybrid/config.h)")
      ->check(CLI::Range(0, 65535))
      ->capture_default_str();
  sub.add_option("--bro-kernel", h.bro_kernel, "Side of the square structuring element of BRO")
      ->check(CLI::Range(1, 63))
      ->capture_default_str();
  sub.add_option("--unconfident", a.unconfident,
                 "What a mask pixel below --tau1 tells Observation Fusion: unobserved (nothing; see hybrid/fusion.h) "
                 "or background (eq. 2 as written)")
      ->check(CLI::IsMember({"unobserved", "background"}))
      ->capture_default_str();
  sub.add_option("--background-vote", h.background_vote,
                 "Weight of a background observation in Observation Fusion's evidence (eq. 4; 1 = the paper; see "
                 "hybrid/fusion.h)")
      ->check(CLI::Range(0.0, 1.0))
      ->capture_default_str();
  sub.add_flag("--occlusion-test,!--no-occlusion-test", h.occlusion_test,
               "Observation Fusion counts a view only where the Gaussian is not hidden behind the surface the "
               "model renders there (on by default; one extra render per view at each table rebuild; see "
               "hybrid/fusion.h). --no-occlusion-test = eq. 3's V");
  sub.add_option("--bro-gradient", a.bro_gradient,
                 "scale-invariant (BRO cannot fade a whole object; see hybrid/bro.h) or plain (eq. 14's own gradient)")
      ->check(CLI::IsMember({"scale-invariant", "plain"}))
      ->capture_default_str();
  sub.add_option("--bro-norm", a.bro_norm,
                 "image (eq. 14 weighted by its band's share of the image, like eq. 6; see hybrid/bro.h) or band "
                 "(eq. 14 as written)")
      ->check(CLI::IsMember({"image", "band"}))
      ->capture_default_str();
  sub.add_flag("--sem-geometry", h.sem_geometry,
               "Let the semantic loss (eq. 10) move opacities and geometry too (default: it trains f and q only)");
  sub.add_option("--lr-lang", h.lr_lang, "Adam learning rate of the language embeddings")->capture_default_str();
  sub.add_option("--lang-storage", a.lang_storage,
                 "Language embeddings in half precision with bfloat16 Adam moments (half), or all float32 (f32)")
      ->check(CLI::IsMember({"half", "f32"}))
      ->capture_default_str();
  sub.add_option("--lr-view", h.lr_view, "Adam learning rate of the view reliability logits")->capture_default_str();
}

// The run's options: batch, length, images, threads, schedule, checkpoints.
void add_run_options(CLI::App& sub, TrainArgs& a) {
  sub.add_option("--batch", a.batch,
                 "Views per step on this process: their gradients are averaged (learning rates unchanged); under "
                 "mpirun each of R ranks takes this many, R x B per step (docs/scaling.md)")
      ->check(CLI::Range(1, 4096))
      ->capture_default_str();
  sub.add_option("--iters", a.iters,
                 "Training images to see (steps x views per step); the 30k densification schedule is scaled to this")
      ->check(CLI::Range(1, 10000000))
      ->capture_default_str();
  sub.add_option("--downscale", a.downscale, "Integer image downscale factor")
      ->check(CLI::Range(1, 64))
      ->capture_default_str();
  sub.add_option("--threads", a.threads, "Worker threads (0 = all cores)")->check(CLI::Range(0, 1024));
  sub.add_option("--seed", a.seed, "Random seed (view order, split sampling)")->capture_default_str();
  sub.add_option("--sh-degree", a.sh_degree, "Maximum SH degree")->check(CLI::Range(0, 3))->capture_default_str();
  sub.add_option(
         "--batch-lr", a.batch_lr,
         "Learning-rate rule for several views per step (--batch x ranks = G): none (rates and Adam betas "
         "as at one view), sqrt (rates x sqrt(G), betas^G, as Grendel) or sqrt-rates (rates x sqrt(G) only); see "
         "train/config.h")
      ->check(CLI::IsMember({"none", "sqrt", "sqrt-rates"}))
      ->capture_default_str();
  sub.add_option("--test-every", a.test_every,
                 "Score the held-out views (PSNR, SSIM) every N images seen and at the end; the curve, with the "
                 "training time to each point, goes to train_stats.json (0 = off)")
      ->check(CLI::Range(0, 10000000))
      ->capture_default_str();
  sub.add_option("--save-every", a.save_every,
                 "Write a checkpoint and a PLY every N iterations (0 = off; a multiple of the views per step)")
      ->check(CLI::Range(0, 10000000))
      ->capture_default_str();
  sub.add_option("--resume", a.resume, "Continue from a checkpoint (MODEL/checkpoints/iter_N.ckpt)");
  sub.add_flag("--no-densify", a.no_densify, "Keep the Gaussian count fixed (no clone/split/prune/opacity reset)");
  sub.add_option("--late-prune", a.late_prune,
                 "After densification stops, every densification interval, prune the Gaussians whose footprint in "
                 "a training view was wider than this fraction of the image's larger side, and the transparent "
                 "ones (0 = off; against floaters near the camera path, docs/scaling.md)")
      ->check(CLI::Range(0.0, 1000.0))
      ->excludes("--no-densify")
      ->capture_default_str();
  sub.add_flag("--white-bg", a.white_bg, "White background (default black)");
  sub.add_option("--near-plane", a.near_plane,
                 "Cull Gaussians nearer than this to a camera (scene units), in training and, through "
                 "MODEL/config.json, wherever the model is rendered; 3DGS uses 0.2")
      ->check(CLI::PositiveNumber)
      ->capture_default_str();
  sub.add_flag("--quiet", a.quiet, "No progress output");
}

CommandRegistration reg({"train",
                         "Optimise Hybrid Gaussians (or plain 3DGS with --method rgb) on a scene's training views", 20,
                         [](CLI::App& sub) {
                           auto a = std::make_shared<TrainArgs>();
                           sub.add_option("SCENE", a->scene, "Scene folder (images/, sparse/0/, ...)")->required();
                           sub.add_option("--out", a->out, "Output model folder")->required();
                           sub.add_option("--method", a->method,
                                          "hybrid (Hybrid Gaussians: objects + language) or rgb (plain 3DGS)")
                               ->check(CLI::IsMember({"hybrid", "rgb"}))
                               ->capture_default_str();
                           add_hybrid_options(sub, *a);
                           add_run_options(sub, *a);
                           return [a] { run_train(*a); };
                         }});

}  // namespace
}  // namespace hgs::cli
