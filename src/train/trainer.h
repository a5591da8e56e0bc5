// Trainer: the 3DGS optimisation loop for one GaussianModel over a set of posed training images. One call to
// step() = pick the next view of a seeded shuffled order, render, L = 0.8 L1 + 0.2 (1 - SSIM), backward, Adam
// (lrs of TrainConfig, position lr decaying with the iteration), SH degree schedule, densification and opacity
// resets. Methods that add per-Gaussian parameters or losses (the hybrid method) subclass it and use the
// hooks; checkpoints hold everything needed to resume bit-for-bit (model, Adam, statistics, RNG, view order).
#pragma once
#include <filesystem>
#include <map>
#include <random>
#include <string>
#include <vector>

#include "core/image.h"
#include "model/gaussian_model.h"
#include "render/renderer.h"
#include "train/adam.h"
#include "train/config.h"
#include "train/densify.h"
#include "train/loss.h"

namespace hgs::train {

struct TrainView {
  std::string name;
  render::Camera cam;
  Image image;  // [H, W, 3]
};

// Wall time of the parts of one step (ms), in step order.
struct StepTimes {
  double prepare = 0;      // the method's per-view inputs (prepare_inputs)
  double forward = 0;      // render forward
  double loss = 0;         // photometric loss and its gradient
  double method_loss = 0;  // the method's losses (extra_loss)
  double backward = 0;     // render backward
  double param_grads = 0;  // the method's chain rule to its parameters (extra_param_grads)
  double update = 0;       // Adam and the method's own updates (method_update)
  double densify = 0;      // densification, opacity reset and after_step
  template <class F> static void each(F&& f) {  // f(name, member pointer) for every part
    f("prepare", &StepTimes::prepare);
    f("forward", &StepTimes::forward);
    f("loss", &StepTimes::loss);
    f("method_loss", &StepTimes::method_loss);
    f("backward", &StepTimes::backward);
    f("param_grads", &StepTimes::param_grads);
    f("update", &StepTimes::update);
    f("densify", &StepTimes::densify);
  }
};

struct StepInfo {
  LossValues loss;
  float psnr = 0;   // of this step's training view
  int num_gaussians = 0;
  double ms = 0;    // wall time of the step
  StepTimes times;  // ... and of its parts
  bool densified = false;
  DensifyResult densify;
};

class Trainer {
 public:
  Trainer(const TrainConfig& cfg, GaussianModel model, std::vector<TrainView> views, float extent);
  virtual ~Trainer() = default;
  Trainer(const Trainer&) = delete;
  Trainer& operator=(const Trainer&) = delete;

  StepInfo step();
  int iteration() const { return it_; }  // iterations done
  int active_sh_degree() const;
  const GaussianModel& model() const { return model_; }
  GaussianModel& model() { return model_; }
  const TrainConfig& config() const { return cfg_; }
  float extent() const { return extent_; }
  const Adam& adam() const { return adam_; }
  const std::vector<TrainView>& views() const { return views_; }

  // Binary checkpoint (see checkpoint.cpp for the layout). Writes atomically.
  void save_checkpoint(const std::filesystem::path& path) const;
  // Restores a checkpoint written by save_checkpoint of a trainer of the same kind; the training views
  // must be the same (checked by count). The checkpoint's configuration replaces cfg except for `iters`
  // and `save_every`, so a run can be extended.
  void load_checkpoint(const std::filesystem::path& path);

 protected:
  // Hooks for derived methods (all default to nothing).
  // Called before forward with the view about to be rendered: may set extra channels or colours on `in` and
  // change the render settings (background, pixel weights, ...).
  virtual void prepare_inputs(const TrainView& view, render::GaussianInputs& in, render::RenderSettings& rs) {}
  // Called after the photometric loss: may add loss terms, accumulate into `d_rgb` [H, W, 3] and set other
  // output gradients in `dout` (pointers must stay valid until backward). Returns the added loss value.
  virtual float extra_loss(const TrainView& view, const render::RenderOutputs& out, float* d_rgb,
                           render::OutputGrads& dout) { return 0.f; }
  // Called after backward with the renderer's gradients (the method adds its own parameters' chain rule).
  virtual void extra_param_grads(render::GaussianGrads& g) {}
  // Called after the built-in Adam updates, before densification: parameters the method optimises itself
  // (registered in adam_ so that their moments follow densification and checkpoints).
  virtual void method_update() {}
  // Called at the end of every step (after Adam and densification).
  virtual void after_step(StepInfo& info) {}
  // Frees the per-step buffers (renderer workspace, gradients, outputs) before densification, so that the row
  // gathers of a large model do not stack on top of them; methods add their own and call this one.
  virtual void release_step_buffers();
  // The method's own state for checkpoints: its options (JSON, null = none) and named float arrays (saved as
  // they are). On load, method_state_loaded() gets the saved options, the checkpoint's Gaussian count and the
  // arrays read by name (sized by the file); it checks them, throwing hgs::Error naming `where` before it
  // changes anything, then takes them and rebuilds what derives from them.
  virtual nlohmann::json method_config() const { return nullptr; }
  virtual std::vector<std::pair<std::string, std::vector<float>>> method_state() const { return {}; }
  virtual void method_state_loaded(const std::string& where, const nlohmann::json& config, int n,
                                   std::map<std::string, std::vector<float>>& arrays) {}

  TrainConfig cfg_;
  GaussianModel model_;
  std::vector<TrainView> views_;
  float extent_;
  int it_ = 0;
  Adam adam_;
  DensifyStats stats_;
  std::mt19937_64 rng_;
  std::vector<int> order_;
  size_t order_pos_ = 0;
  render::GaussianRenderer renderer_;
  render::RenderOutputs out_;
  render::GaussianGrads grads_;
  PhotometricLoss loss_;
  std::vector<float> d_rgb_;  // [H, W, 3]

 private:
  int next_view();
};

}  // namespace hgs::train
