// 3DGS adaptive density control. Statistics: for every Gaussian visible in a view, the norm of the gradient
// of the loss with respect to its projected 2D centre measured in NDC units (pixel gradient x (W/2, H/2)) is
// accumulated, with a visibility count and the largest screen radius. Every densification step:
//   - clone Gaussians whose mean gradient >= threshold and max scale <= percent_dense x extent (copy);
//   - split those with mean gradient >= threshold and max scale > percent_dense x extent into 2 children
//     with centres sampled from the parent Gaussian and scales / 1.6 (0.8 x 2); the parent is removed;
//   - prune opacity < min_opacity and, when `screen_limit` > 0, max screen radius > screen_limit px or max
//     world scale > max_world_scale x extent.
// Rows are reordered as in 3DGS: survivors, clones, then children. Adam moments follow their Gaussians; new
// Gaussians (clones, children) start with zero moments as in 3DGS (torch.cat with zeros).
#pragma once
#include <random>
#include <vector>

#include "model/gaussian_model.h"
#include "train/adam.h"

namespace hgs::train {

struct DensifyConfig {
  float grad_threshold = 2e-4f;
  float percent_dense = 0.01f;
  float min_opacity = 0.005f;
  float max_world_scale = 0.1f;  // x extent
  int split_children = 2;
  float split_scale_div = 1.6f;  // 0.8 x split_children
};

// The densification statistics of one step's views before they reach DensifyStats: per Gaussian the sum of the
// views' NDC-gradient norms, the number of views it was visible in, and its largest radius. As one float array
// [3, N] (norm sums, counts, max radii), so the trainer sends it with the gradients (sums) and the radii (max).
struct StepStats {
  int n = 0;
  std::vector<float> v;  // [3, N]
  float* norm() { return v.data(); }
  float* count() { return v.data() + n; }
  float* max_radius() { return v.data() + 2 * size_t(n); }
  const float* norm() const { return v.data(); }
  const float* count() const { return v.data() + n; }
  const float* max_radius() const { return v.data() + 2 * size_t(n); }
  // Adds one view (first = the step's first view: overwrites). Same arithmetic as DensifyStats::add, so one view
  // per step gives the same statistics.
  void add_view(const float* mean2d_grad, const int* radii, int n, int W, int H, bool first);
};

struct DensifyStats {
  std::vector<float> grad_accum;  // [N] sum of NDC-gradient norms
  std::vector<int> count;         // [N] views in which the Gaussian was visible
  std::vector<float> max_radius;  // [N] largest screen radius (px)

  void reset(int n);
  // One view: mean2d_grad [N, 2] in pixels, radii [N] (0 = not visible), image size W x H.
  void add(const float* mean2d_grad, const int* radii, int n, int W, int H);
  // One step of several views (--batch, MPI): the step's sums (StepStats) added at once.
  void add(const StepStats& s);
};

struct DensifyResult {
  int cloned = 0, split = 0, pruned = 0;
};

// Clone, split and prune (in that order); resets the statistics. `screen_limit` <= 0 disables the screen
// and world size pruning (3DGS enables them only after the first opacity reset).
DensifyResult densify_and_prune(GaussianModel& model, Adam& adam, DensifyStats& stats, const DensifyConfig& cfg,
                                float extent, float screen_limit, std::mt19937_64& rng);

// The prune of densify_and_prune alone (no clone or split); resets the statistics. For `TrainConfig::late_prune`,
// after densification has stopped (with cfg.max_world_scale infinite and the footprint limit it sets).
DensifyResult prune_step(GaussianModel& model, Adam& adam, DensifyStats& stats, const DensifyConfig& cfg, float extent,
                         float screen_limit);

// Removes the Gaussians with mask[i] != 0 from the model, Adam and the statistics. Returns the count removed.
int prune_gaussians(GaussianModel& model, Adam& adam, DensifyStats& stats, const std::vector<char>& mask);

// 3DGS opacity reset: opacity = min(opacity, max_opacity) and the opacity moments zeroed.
void reset_opacity(GaussianModel& model, Adam& adam, float max_opacity = 0.01f);

}  // namespace hgs::train
