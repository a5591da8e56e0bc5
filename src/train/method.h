// Method: what a training method adds to the 3DGS step, plugged into train::Trainer by composition (compare
// LichtFeld Studio's strategy interface and gsplat's Strategy). Plain 3DGS is the method that adds nothing;
// Hybrid Gaussians (hybrid/method.h) is another. The trainer owns the model, the optimiser (every parameter, the
// method's included, is registered there), the renderer, the view order and the schedule. A method keeps no
// pointer to the model: every hook receives what it reads and writes as arguments, valid during the call.
//
// A step sees a global batch of G views (`--batch` views on each MPI rank; G = 1 by default). The trainer calls,
// for each view of this process (ViewStep says which):
//   prepare   between the renderer's preprocess (projection, SH colours of the visible Gaussians, binning) and
//             its composite: set extra channels (e.g. built from the projected colours) and pixel weights
//   losses    after the photometric loss: add weighted terms to the objective and write output gradients
//             (add to d_rgb, set dout.extra / dout.weight_sums; the pointers must stay valid until backward)
//   backward  between the renderer's composite_backward and preprocess_backward: chain the projected-space
//             gradients (d channels, d colours, ...) into the method's parameters, and add to them (e.g. the
//             colour gradient of channels built from the projected colours) before they reach SH and geometry.
//             The method's own parameter gradients are summed over the step's views here, never applied: every
//             view of a step sees the same parameters
// then once per step:
//   reduce      combine those sums across ranks (rank order), so that every rank holds the global batch's sum
//   update      after Adam on the 3DGS parameters: Adam steps of the method's registered parameters with the batch
//               mean (sum x grad_scale)
//   after_step  after densification and opacity resets (the model and every per-Gaussian moment follow them)
//
// Checkpoints hold every registered parameter (values and moments) without per-method code; state() is only for
// what is neither a parameter nor derivable (the hybrid method's observation table). stats() reports diagnostics
// of the last step by name, for progress lines, benchmarks, tools and tests.
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

// The view a per-view hook works on, and the model of the step.
struct ViewStep {
  int iteration;   // 1-based: training images seen before this step + 1 (the schedules count images)
  int view_index;  // into the trainer's views
  const TrainView& view;
  int slot;              // this process's view number within the step, 0 .. batch - 1
  int global_slot;       // the view's number within the global batch, rank x batch + slot
  std::mt19937_64& rng;  // with one view per step the trainer's stream; with several this view's own, seeded from
                         // (seed, iteration, global_slot), so any split of a batch over ranks draws the same numbers
  GaussianModel& model;
};

// prepare: the renderer's preprocess results in, what composite renders out.
struct PrepareIO {
  const render::ProjectedView<float>& projected;  // colours [N, 3], radii, ... of this view
  render::Channels& channels;                     // extra channels to composite (none unless set)
  render::RenderSettings& settings;               // e.g. pixel weights for per-Gaussian weighted sums
};

// losses: the rendered view in, loss terms and output gradients out.
struct LossIO {
  const render::RenderOutputs& out;
  float* d_rgb;  // [H, W, 3] dL/d rgb, holding the photometric term's weighted gradient (also dout.rgb)
  render::OutputGrads& dout;
  Objective& objective;
};

// backward: gradients of the projected quantities (composite_backward's result), before preprocess_backward.
struct BackwardIO {
  const render::ProjectedView<float>& projected;
  render::ProjectedGrads& grads;  // d colours, d channels, d mean2d, ...
};

// update: once per step, after Adam on the 3DGS parameters.
struct UpdateIO {
  int iteration;     // the step's first image (1-based)
  int step_views;    // G: views of the global batch
  float grad_scale;  // 1 / G: the update uses the mean over the global batch
  GaussianModel& model;
  Adam& optim;
  const render::GaussianGrads& grads;  // the 3DGS parameters' gradients of the step (the batch mean)
};

// after_step: once per step, after densification.
struct StepEnd {
  int iteration;    // the step's first image (1-based)
  int images_seen;  // after the step: iteration - 1 + G
  bool densified;
  GaussianModel& model;
};

// Diagnostics of the last step, by name (nothing in training reads them).
struct MethodStats {
  std::vector<std::pair<std::string, double>> values;
  std::vector<std::pair<std::string, std::vector<float>>> arrays;
  // The named value / array; throws hgs::Error when the method reports none of that name.
  double value(const std::string& name) const;
  const std::vector<float>& array(const std::string& name) const;
};

class Method {
 public:
  virtual ~Method() = default;
  virtual std::string name() const = 0;
  // Once, when the trainer is built (after it registered the 3DGS parameters): add model extras, register the
  // method's parameters in `optim`. A parameter's `values` function may keep a reference to `model`: it is the
  // trainer's and lives as long as the trainer.
  virtual void attach(GaussianModel& /*model*/, Adam& /*optim*/, const std::vector<TrainView>& /*views*/) {}
  // Weight of the 3DGS photometric term ("rgb").
  virtual float rgb_weight() const { return 1.f; }
  virtual void prepare(const ViewStep& /*v*/, const PrepareIO& /*io*/) {}
  virtual void losses(const ViewStep& /*v*/, const LossIO& /*io*/) {}
  virtual void backward(const ViewStep& /*v*/, const BackwardIO& /*io*/) {}
  virtual void reduce(Reducer& /*reducer*/) {}
  virtual void update(const UpdateIO& /*io*/) {}
  virtual void after_step(const StepEnd& /*end*/) {}
  // Frees per-step buffers before densification.
  virtual void release() {}
  virtual MethodStats stats() const { return {}; }
  // Options saved with checkpoints (null = none) and their restore (may throw hgs::Error naming `where`;
  // must not change anything then).
  virtual nlohmann::json config() const { return nullptr; }
  // Non-parameter state for checkpoints: named float arrays. On load, state_loaded() gets the saved options,
  // the checkpoint's Gaussian count and the arrays (sized by the file); it checks them, throwing hgs::Error
  // naming `where` before it changes anything, then takes them.
  virtual std::vector<std::pair<std::string, std::vector<float>>> state() const { return {}; }
  virtual void state_loaded(const std::string& /*where*/, const nlohmann::json& /*config*/, int /*n*/,
                            std::map<std::string, std::vector<float>>& /*arrays*/) {}
};

// Plain 3DGS: adds nothing.
class RgbMethod final : public Method {
 public:
  std::string name() const override { return "rgb"; }
};

}  // namespace hgs::train
