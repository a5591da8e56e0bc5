// Method: what a training method adds to the 3DGS step, plugged into train::Trainer by composition (compare
// LichtFeld Studio's strategy interface and gsplat's Strategy). Plain 3DGS is the method that adds nothing;
// Hybrid Gaussians (hybrid/method.h) is another. The trainer owns the model, the optimiser (every parameter,
// the method's included, is registered there), the renderer, the view order and the schedule; it calls the
// method's parts in this order. A step sees a global batch of G views (`--batch` views on each MPI rank; G = 1
// by default): prepare, losses and backward run once per view of this process, then reduce, update and
// after_step once per step.
//
//   prepare   between the renderer's preprocess (projection, SH colours of the visible Gaussians, binning) and
//             its composite: set extra channels (e.g. built from the projected colours) and pixel weights
//   losses    after the photometric loss: add weighted terms to the objective, write output gradients
//             (accumulate into d_rgb, set dout.extra / dout.weight_sums; pointers valid until backward)
//   backward  between the renderer's composite_backward and preprocess_backward: chain the projected-space
//             gradients (d channels, d colours, ...) into the method's parameters, and add to them (e.g. the
//             colour gradient of channels built from the projected colours) before they reach SH and geometry.
//             The method's own parameter gradients are summed over the step's views here, never applied: every
//             view of a step sees the same parameters
//   reduce    after the last view: combine those sums across ranks (c.reducer, rank order), so that every rank
//             holds the global batch's sum
//   update    after Adam on the 3DGS parameters: Adam steps of the method's registered parameters with the
//             batch mean (sum x c.grad_scale)
//   after_step  after densification (the model and every per-Gaussian moment already follow it)
//
// Checkpoints hold every registered parameter (values and moments) without per-method code; state() is only
// for what is neither a parameter nor derivable (the hybrid method's observation table).
#pragma once
#include <map>
#include <random>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/image.h"
#include "model/gaussian_model.h"
#include "render/renderer.h"
#include "train/adam.h"
#include "train/objective.h"
#include "train/reducer.h"

namespace hgs::train {

struct TrainView {
  std::string name;
  render::Camera cam;
  Image image;  // [H, W, 3]
};

// Everything one step's parts see. Fields are filled as the step proceeds (out after the render, grads after
// the renderer's backward).
struct StepContext {
  int iteration = 0;   // 1-based: training images seen before this step + 1 (the schedules count images)
  int view_index = 0;  // into the trainer's views
  int slot = 0;        // this process's view number within the step, 0 .. batch - 1
  int global_slot = 0; // the view's number within the global batch, rank x batch + slot
  int step_views = 1;  // G: views of the global batch
  float grad_scale = 1;  // 1 / G: the update uses the mean over the global batch
  Reducer* reducer = nullptr;
  const TrainView* view = nullptr;
  GaussianModel* model = nullptr;
  Adam* optim = nullptr;
  std::mt19937_64* rng = nullptr;  // one view per step: the trainer's; several: this view's, seeded from
                                   // (seed, iteration, global_slot), so any split of a batch over ranks draws the
                                   // same numbers
  render::GaussianInputs* inputs = nullptr;
  const render::ProjectedView<float>* projected = nullptr;  // after preprocess: colours [N, 3], radii, ...
  render::Channels* channels = nullptr;                     // extra channels to composite (set by prepare)
  render::RenderSettings* settings = nullptr;
  const render::RenderOutputs* out = nullptr;
  float* d_rgb = nullptr;  // [H, W, 3] dL/d rgb, already holding the photometric term's weighted gradient
  render::OutputGrads* dout = nullptr;
  render::ProjectedGrads* pgrads = nullptr;  // after composite_backward (d colours, d channels, d mean2d, ...)
  render::GaussianGrads* grads = nullptr;    // after preprocess_backward (the 3DGS parameters)
  Objective* objective = nullptr;
  int sh_degree = 0;  // active SH degree of this step
};

class Method {
 public:
  virtual ~Method() = default;
  virtual std::string name() const = 0;
  // Once, when the trainer is built (after it registered the 3DGS parameters): add model extras, register the
  // method's parameters in `optim`.
  virtual void attach(GaussianModel& model, Adam& optim, const std::vector<TrainView>& views) {}
  // Weight of the 3DGS photometric term ("rgb").
  virtual float rgb_weight() const { return 1.f; }
  virtual void prepare(StepContext& c) {}
  virtual void losses(StepContext& c) {}
  virtual void backward(StepContext& c) {}
  virtual void reduce(StepContext& c) {}
  virtual void update(StepContext& c) {}
  virtual void after_step(StepContext& c, bool densified) {}
  // Frees per-step buffers before densification.
  virtual void release() {}
  // Options saved with checkpoints (null = none) and their restore (may throw hgs::Error naming `where`;
  // must not change anything then).
  virtual nlohmann::json config() const { return nullptr; }
  // Non-parameter state for checkpoints: named float arrays. On load, state_loaded() gets the saved options,
  // the checkpoint's Gaussian count and the arrays (sized by the file); it checks them, throwing hgs::Error
  // naming `where` before it changes anything, then takes them.
  virtual std::vector<std::pair<std::string, std::vector<float>>> state() const { return {}; }
  virtual void state_loaded(const std::string& where, const nlohmann::json& config, int n,
                            std::map<std::string, std::vector<float>>& arrays) {}
};

// Plain 3DGS: adds nothing.
class RgbMethod final : public Method {
 public:
  std::string name() const override { return "rgb"; }
};

}  // namespace hgs::train
