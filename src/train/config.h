// TrainConfig: every hyper-parameter of RGB Gaussian training, with the 3DGS defaults for a 30k-iteration run,
// JSON (de)serialisation for MODEL/config.json and checkpoints, and the proportional schedule scaling to
// another iteration count.
#pragma once
#include <cstdint>
#include <nlohmann/json.hpp>
#include <string>

#include "render/renderer.h"
#include "train/densify.h"

namespace hgs::train {

// Whether r names a rule of TrainConfig::batch_lr (none, sqrt, sqrt-rates).
bool is_batch_lr_rule(const std::string& r);

struct TrainConfig {
  std::string method = "rgb";
  int iters = 30000;
  int sh_degree = 3;  // maximum SH degree
  bool densify = true;
  bool white_bg = false;
  // Camera-space depth below which Gaussians are culled in training and, through MODEL/config.json, wherever the
  // model is rendered (model/near_plane.h). 3DGS's rasterizer uses 0.2 scene units (COLMAP scenes normalised to
  // a camera extent of about 10); the default keeps gsplat's 0.01 (docs/scaling.md, "The near plane").
  float near_plane = render::kDefaultNearPlane;
  uint64_t seed = 0;
  float lambda_dssim = 0.2f;
  // Learning rates (3DGS). Positions are scaled by the scene extent and decay log-linearly over `iters`.
  float lr_position_init = 1.6e-4f, lr_position_final = 1.6e-6f;
  float lr_sh_dc = 2.5e-3f, lr_sh_rest = 2.5e-3f / 20.f;
  float lr_opacity = 0.05f, lr_scaling = 5e-3f, lr_rotation = 1e-3f;
  int sh_increase_every = 1000;
  // Densification schedule (the 30k values; see scaled_to).
  int densify_from = 500, densify_until = 15000, densify_every = 100, opacity_reset_every = 3000;
  float screen_limit = 20.f;  // px, used after the first opacity reset
  // > 0: after densification stops at densify_until, every densify_every images, prune the Gaussians whose
  // 3-sigma footprint in a training view of the interval was wider than late_prune x the view's larger side, and
  // the transparent ones (no clone, split, opacity reset or world-size rule; 3DGS prunes only while densifying).
  // 0 = off, the default: an option against floaters near the camera path (docs/scaling.md, "Floaters"), where
  // 3DGS's own rules applied late (20 px, 0.1 x extent) would empty a model.
  float late_prune = 0.f;
  DensifyConfig densify_cfg;
  int save_every = 0;  // checkpoint + PLY every N iterations (0 = never during training)
  // Views per step on this process (--batch); a step of R MPI ranks sees R x batch views. Every iteration count
  // here (iters, the schedules, save_every) counts training images seen, so it does not depend on the batch.
  int batch = 1;
  // Learning-rate rule for G = batch x ranks views per step. "none": every rate and Adam's betas as at one view
  // (the gradient is the mean over the G views). "sqrt": Grendel's rule (Zhao et al. 2024, "On Scaling Up 3D
  // Gaussian Splatting Training"): every rate times sqrt(G) and betas beta^G, so that after the same number
  // of images the moments have decayed as much as with one view per step. "sqrt-rates": the rates times sqrt(G),
  // the betas unchanged. G = 1 is the same step under every rule.
  std::string batch_lr = "none";

  // Copy for a run of `iterations` with the 30k densification schedule scaled by f = iterations / 30000:
  // densify_until = 15000 f; for short runs (f < 1) three floors keep the 3DGS dynamics, because compressing
  // the schedule densifies unconverged Gaussians every few steps and multiplies the count (docs/results.md,
  // "Figures behind defaults"):
  //   densify_every = max(100 f, 100)   (the averaged gradient covers ~100 steps, as in 3DGS)
  //   densify_from  = max(500 f, min(500, iterations / 10))
  //   opacity_reset_every = max(3000 f, 10 x densify_every)
  // For f >= 1 everything is plainly proportional. The SH schedule stays at one degree per
  // `sh_increase_every` iterations.
  TrainConfig scaled_to(int iterations) const;
  // Position learning rate at 1-based iteration `it` for a scene of the given extent.
  float position_lr(int it, float extent) const;

  nlohmann::json to_json() const;
  static TrainConfig from_json(const nlohmann::json& j, const std::string& where);
};

}  // namespace hgs::train
