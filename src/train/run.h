// One training run: the loop behind `hgs train`, `hgs ablate`, the depth model of `hgs prepare` / `hgs masks
// associate` and Python's hgs.train. It steps a Trainer until the run's last image (or until the per-step
// callback stops it), keeps a moving average of the loss, writes checkpoints every save_every images, scores the
// held-out views every test_every images, and owns the model folder's layout (docs/formats.md):
//   OUT/config.json                                   the run's configuration (run_config), before the first step
//   OUT/checkpoints/iter_<N>.ckpt, point_cloud_iter_<N>.ply   every save_every images (and the last checkpoint)
//   OUT/point_cloud.ply, OUT/train_stats.json          at the end (TrainingRun::save)
// Every file is written atomically (core/fs.h).
#pragma once
#include <filesystem>
#include <functional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/image.h"
#include "core/progress.h"
#include "scene/scene.h"
#include "train/trainer.h"

namespace hgs::train {

struct RunOptions {
  std::filesystem::path out;  // the model folder; empty: nothing is written
  int iters = 0;              // training images to see in all (0: the trainer's config().iters)
  int save_every = 0;         // a checkpoint and a PLY every N images (0: none; needs `out`)
  int test_every = 0;         // held-out PSNR / SSIM every N images and at the end (0: none)
  bool writer = true;         // this process writes the files and shows progress (MPI: rank 0 only)
  bool progress = false;      // a progress bar on stderr
  std::string label = "train";
  std::string resumed_from;  // the checkpoint the trainer was loaded from ("" = a new run)
};

// Exponential moving averages (weight 0.4 on the newest step) of the optimised total, each weighted term in the
// objective's order, and the training views' PSNR.
struct LossAverage {
  double loss = 0, psnr = 0;
  std::vector<std::pair<std::string, double>> terms;
  void add(const StepInfo& s, bool first);
  std::string terms_text() const;     // " (rgb 0.1234 app 0.0100 ...)" with more than one term, else ""
  nlohmann::json terms_json() const;  // {"rgb": ..., "app": ...}: they sum to the total
};

// What the per-step callback sees, after the step.
struct RunStep {
  const StepInfo& step;
  int iteration;  // images seen so far
  int start;      // ... when this run started (a resumed run starts at its checkpoint)
  int iters;      // ... at the end of the run
  const LossAverage& average;
  double elapsed_s;  // since the run started
};
// Returns false to end the run after this step; the model so far is kept (TrainingRun::save writes it).
using StepCallback = std::function<bool(const RunStep&)>;

// MODEL/config.json: the trainer's configuration, the method's options (under "hybrid" for the hybrid method),
// the scene (absolute path, downscale, split), the extent, the training views, the initial point count and the
// number of MPI ranks (the trainer's reducer). `init_points`: the model's size before any checkpoint was loaded.
nlohmann::json run_config(const Trainer& trainer, const Scene& scene, const nlohmann::json& method_options,
                          int init_points);

class TrainingRun {
 public:
  // Checks the run against the trainer (images left to see a multiple of the step's G views, save_every a
  // multiple of G and given an output folder, held-out views for test_every) and, on the writer with an output
  // folder, makes the folder and writes config.json (`config`, with "resumed_from" added for a resumed run).
  TrainingRun(Trainer& trainer, const Scene& scene, RunOptions opt, nlohmann::json config);

  // Steps until the last image or until `on_step` returns false (stopped() is then "callback" unless the
  // callback named another reason with stop_reason). A failing step (a non-finite loss or gradient) throws
  // hgs::Error naming the last checkpoint written, which stays intact.
  void train(const StepCallback& on_step = {});
  // The reason recorded in train_stats.json's "stopped" when the callback ends the run (e.g. "interrupted").
  void stop_reason(std::string why) { stop_reason_ = std::move(why); }
  // "" when the run went to its last image, else why it ended early.
  const std::string& stopped() const { return stopped_; }

  // train_stats.json (docs/formats.md).
  nlohmann::json stats() const;
  // On the writer with an output folder: point_cloud.ply, the final checkpoint (with save_every) and
  // train_stats.json. Returns stats().
  nlohmann::json save() const;
  // The closing lines of `hgs train`: steps, time, Gaussians, the mean time of each part of a step.
  std::string summary() const;

 private:
  std::string snapshot(bool with_ply) const;  // checkpoints/iter_<N>.ckpt (+ point_cloud_iter_<N>.ply)
  void score_held_out(int it, Progress& bar, double elapsed);

  Trainer& trainer_;
  const Scene& scene_;
  RunOptions opt_;
  int start_ = 0;
  std::string last_ckpt_, stopped_, stop_reason_;
  LossAverage average_;
  // What the run measured.
  std::vector<float> ms_;              // wall ms of each step
  std::vector<int> iter_;              // the images seen at the end of each step
  std::vector<float> densify_ms_;      // ... and its densification / opacity reset / after_step part
  StepTimes parts_;                    // summed over the steps
  std::vector<StepTimes> step_parts_;  // each step's parts
  double wall_ = 0;                    // seconds, held-out scoring included
  // The held-out curve (test_every).
  std::vector<int> test_views_;
  std::vector<Image> test_images_;
  nlohmann::json curve_ = nlohmann::json::array();
  double test_seconds_ = 0;
};

}  // namespace hgs::train
