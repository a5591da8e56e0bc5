// `hgs train SCENE --out MODEL [--method hybrid|rgb]`: Hybrid Gaussians (default) or plain 3DGS training. Writes
// MODEL/point_cloud.ply (3DGS layout), MODEL/config.json, MODEL/train_stats.json and, with --save-every,
// MODEL/checkpoints/iter_<N>.ckpt (+ the final one) for --resume.
#include <omp.h>

#include <csignal>
#include <cstdio>
#include <cstdlib>

#include <algorithm>
#include <optional>
#include <string>
#include <vector>

#include "cli/command.h"
#include "core/error.h"
#include "hybrid/config.h"
#include "hybrid/register.h"
#include "mpi/session.h"
#include "scene/scene.h"
#include "train/registry.h"
#include "train/run.h"

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

void run_train(const TrainArgs& a) {
  // Under mpirun every rank runs this same function on the same scene and configuration; rank 0 alone writes
  // outputs and shows progress (docs/scaling.md).
  mpi::Session mpi;
  const int R = mpi.size();
  const bool writer = mpi.rank() == 0, progress = !a.quiet && writer;
  // Ranks sharing a machine share its cores: by default each takes its share.
  set_threads(a.threads == 0 && R > 1 ? std::max(1, omp_get_num_procs() / mpi::local_ranks()) : a.threads);
  Scene scene = load_scene(a.scene, {a.downscale, false});
  const std::vector<int> train_idx = scene.train_indices();
  if (train_idx.empty()) fail("{}: the scene has no training views", a.scene);
  check_step_size(a, train_idx.size(), R);

  const std::optional<hybrid::HybridConfig> hc = hybrid_config(a);
  const nlohmann::json method_options = hc ? hc->to_json() : nlohmann::json();
  hybrid::register_method();
  auto trainer_ptr =
      train::make_trainer(scene, train_idx, train_config(a), a.method, method_options, progress, &mpi.reducer());
  train::Trainer& trainer = *trainer_ptr;
  const int init_points = trainer.model().n;
  if (!a.resume.empty()) trainer.load_checkpoint(a.resume);

  train::RunOptions ro;
  ro.out = a.out;
  ro.iters = a.iters;
  ro.save_every = a.save_every;
  ro.test_every = a.test_every;
  ro.writer = writer;
  ro.progress = progress;
  ro.resumed_from = a.resume;
  train::TrainingRun run(trainer, scene, ro, train::run_config(trainer, scene, method_options, init_points));
  const int kill_at = kill_hook(mpi.rank());
  run.train([&](const train::RunStep& s) {
    if (kill_at > 0 && s.iteration >= kill_at) std::raise(SIGKILL);
    return true;
  });
  if (!writer) return;  // every rank holds the same model; rank 0 writes it
  run.save();
  if (progress) fmt::print("{}\n", run.summary());
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
  sub.add_option("--gaps", h.gaps,
                 "What an unlabelled mask pixel tells Observation Fusion: background (eq. 2 as written), unobserved "
                 "(nothing: where the masks cover everything, surfaces too, a gap is a lost track or an eroded edge) "
                 "or auto (unobserved in views whose masks label >= 90 % of the pixels); see hybrid/config.h")
      ->check(CLI::IsMember({"background", "unobserved", "auto"}))
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
  add_threads_option(sub, a.threads);
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
