// Trainer: the 3DGS optimisation loop for one GaussianModel over a set of posed training images, with a Method
// (train/method.h) plugged in by composition. One call to step() takes the next G views of a seeded shuffled
// order (G = cfg.batch x ranks; G = 1 by default), and for each of this process's views: the renderer's
// preprocess, method.prepare, composite, photometric loss L = 0.8 L1 + 0.2 (1 - SSIM) (weighted by the method's
// rgb_weight), method.losses, composite_backward, method.backward, preprocess_backward, gradients summed in view
// order. Then, once per step: the Reducer adds the ranks' sums in rank order (method.reduce its own), Adam on
// the 3DGS parameters (gaussian_params.h) with the batch mean (learning rates of TrainConfig, the position rate
// decaying with the images seen, the batch rule of TrainConfig::batch_lr), method.update, densification and
// opacity resets, method.after_step. Every schedule counts training images seen (iteration() advances by G per step),
// so a run with a larger batch sees the same views at the same schedule points in fewer steps. The trainer owns the
// model, the optimiser (the method registers its parameters there), the renderer and the schedule; checkpoints
// hold everything needed to resume bit for bit (model, every registered parameter and its moments, statistics,
// RNG, view order, method state).
#pragma once
#include <filesystem>
#include <map>
#include <memory>
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
#include "train/method.h"
#include "train/objective.h"
#include "train/reducer.h"

namespace hgs::train {

// Wall time of the parts of one step (ms), in step order.
struct StepTimes {
  double prepare = 0;      // the method's per-view inputs (Method::prepare)
  double forward = 0;      // render forward
  double loss = 0;         // photometric loss and its gradient
  double method_loss = 0;  // the method's losses (Method::losses)
  double backward = 0;     // render backward
  double param_grads = 0;  // the method's chain rule to its parameters (Method::backward)
  double reduce = 0;       // combining the ranks' gradients (Reducer; 0 on one process)
  double update = 0;       // Adam and the method's own updates (Method::update)
  double densify = 0;      // densification, opacity reset and after_step
  template <class F>
  static void each(F&& f) {  // f(name, member pointer) for every part
    f("prepare", &StepTimes::prepare);
    f("forward", &StepTimes::forward);
    f("loss", &StepTimes::loss);
    f("method_loss", &StepTimes::method_loss);
    f("backward", &StepTimes::backward);
    f("param_grads", &StepTimes::param_grads);
    f("reduce", &StepTimes::reduce);
    f("update", &StepTimes::update);
    f("densify", &StepTimes::densify);
  }
};

struct StepInfo {
  LossValues loss;   // of the photometric term (total = its unweighted value); mean over this process's views
  double total = 0;  // the optimised objective: sum of the weighted terms
  std::vector<LossTerm> terms;
  float psnr = 0;  // of this step's training views (from the mean MSE)
  int num_gaussians = 0;
  double ms = 0;    // wall time of the step
  StepTimes times;  // ... and of its parts
  bool densified = false;
  DensifyResult densify;
};

class Trainer {
 public:
  // method null = plain 3DGS (RgbMethod). reducer null = one process; else it is not owned and must outlive
  // the trainer (every rank builds the same trainer: same views, model, config and seed).
  Trainer(const TrainConfig& cfg, GaussianModel model, std::vector<TrainView> views, float extent,
          std::unique_ptr<Method> method = nullptr, Reducer* reducer = nullptr);
  ~Trainer();
  Trainer(const Trainer&) = delete;
  Trainer& operator=(const Trainer&) = delete;

  // One iteration. A non-finite loss term or gradient value (any registered parameter) stops it with an
  // hgs::Error naming the iteration and the term or parameter group; the model is then not to be saved.
  StepInfo step();
  int iteration() const { return it_; }  // training images seen (= steps x views per step)
  int step_views() const;                // G: views of one step over all ranks
  // The SH degree rendered at 1-based iteration `iteration`: one more every sh_increase_every images (3DGS raises
  // it at 1000, 2000, ...), up to the configured maximum.
  int sh_degree_at(int iteration) const;
  const GaussianModel& model() const { return model_; }
  GaussianModel& model() { return model_; }
  const TrainConfig& config() const { return cfg_; }
  float extent() const { return extent_; }
  const Adam& adam() const { return adam_; }
  const std::vector<TrainView>& views() const { return views_; }
  Method& method() { return *method_; }
  Reducer& reducer() { return *reducer_; }
  const Reducer& reducer() const { return *reducer_; }
  const Method& method() const { return *method_; }

  // Binary checkpoint (see checkpoint.cpp for the layout). Writes atomically.
  void save_checkpoint(const std::filesystem::path& path) const;
  // Restores a checkpoint written by save_checkpoint of a trainer of the same kind; the training views
  // must be the same (checked by count). The checkpoint's configuration replaces cfg except for `iters`
  // and `save_every`, so a run can be extended.
  void load_checkpoint(const std::filesystem::path& path);

 private:
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
  render::GaussianGrads grads_;       // the step's sum over its views (then the mean)
  render::GaussianGrads view_grads_;  // of the second and later views of a step
  StepStats step_stats_;
  std::vector<float> pack_;  // the gradients and statistic sums sent to the other ranks
  Reducer local_reducer_;
  Reducer* reducer_ = nullptr;
  render::ProjectedGrads pgrads_;
  PhotometricLoss loss_;
  std::vector<float> d_rgb_;  // [H, W, 3]
  Objective objective_;
  std::unique_ptr<Method> method_;

  int inject_iter_ = 0;  // HGS_INJECT_NAN=<iteration>:<group> (a test hook, see docs/reliability.md)
  std::string inject_group_;

  // The phases of step(), in order (trainer.cpp).
  struct StepPlan;
  struct ViewSums;
  class PartClock;
  StepPlan plan_step();
  void train_view(const StepPlan& plan, int slot, const render::GaussianInputs& in, ViewSums& sums, PartClock& clock,
                  StepTimes& times);
  void render_view(const ViewStep& vs, const render::GaussianInputs& in, float background, PartClock& clock,
                   StepTimes& times);
  void add_view_gradients(int slot);
  void average_views(const ViewSums& sums, StepInfo& info);
  void reduce_step(const StepPlan& plan, PartClock& clock, StepTimes& times);
  void update_parameters(const StepPlan& plan, PartClock& clock, StepTimes& times, StepInfo& info);
  void densify_step(const StepPlan& plan, StepInfo& info);

  void register_gaussian_params();
  void parse_inject_nan();
  void inject_gradient_nan(int it);
  int next_view();
  // Sums the gradients and statistics of the step over the ranks, then scales the gradients by 1 / G.
  void reduce_and_scale(float grad_scale);
  void release_step_buffers();
  // Throws hgs::Error naming iteration `it` and the loss term or parameter group when one was not finite.
  void check_finite(int it) const;
};

}  // namespace hgs::train
