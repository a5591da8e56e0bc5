// The training run of run.h: the step loop with its callback, checkpoints, held-out curve, statistics and the
// model folder.
#include "train/run.h"

#include <omp.h>

#include <algorithm>
#include <chrono>

#include <fmt/format.h>

#include "core/error.h"
#include "core/folder.h"
#include "core/fs.h"
#include "core/process.h"
#include "model/ply.h"
#include "train/held_out.h"

namespace hgs::train {
namespace fs = std::filesystem;
using nlohmann::json;

void LossAverage::add(const StepInfo& s, bool first) {
  loss = first ? s.total : 0.4 * s.total + 0.6 * loss;
  if (first || terms.size() != s.terms.size()) {
    terms.clear();
    for (const auto& t : s.terms) terms.push_back({t.name, t.weighted()});
  } else {
    for (size_t k = 0; k < s.terms.size(); ++k) terms[k].second = 0.4 * s.terms[k].weighted() + 0.6 * terms[k].second;
  }
  psnr = first ? s.psnr : 0.4 * s.psnr + 0.6 * psnr;
}

std::string LossAverage::terms_text() const {
  std::string t;
  if (terms.size() > 1)
    for (const auto& [name, v] : terms) t += fmt::format("{}{} {:.4f}", t.empty() ? " (" : " ", name, v);
  return t.empty() ? t : t + ")";
}

json LossAverage::terms_json() const {
  json j = json::object();
  for (const auto& [name, v] : terms) j[name] = v;
  return j;
}

json run_config(const Trainer& trainer, const Scene& scene, const json& method_options, int init_points) {
  json config = trainer.config().to_json();
  config["scene"] = fs::absolute(scene.root).lexically_normal().string();
  config["downscale"] = scene.downscale;
  config["extent"] = trainer.extent();
  config["train_views"] = trainer.views().size();
  config["init_points"] = init_points;
  config["split"] = scene.split_source;
  if (!method_options.is_null()) config[trainer.config().method] = method_options;
  config["ranks"] = trainer.reducer().size();
  return config;
}

TrainingRun::TrainingRun(Trainer& trainer, const Scene& scene, RunOptions opt, json config)
    : trainer_(trainer), scene_(scene), opt_(std::move(opt)) {
  if (opt_.iters <= 0) opt_.iters = trainer_.config().iters;
  start_ = trainer_.iteration();
  last_ckpt_ = opt_.resumed_from;
  const int G = trainer_.step_views();
  if (start_ >= opt_.iters)
    fail("{} is at iteration {}, nothing to do for {} iterations",
         opt_.resumed_from.empty() ? std::string("the trainer") : opt_.resumed_from + ": checkpoint", start_,
         opt_.iters);
  if ((opt_.iters - start_) % G != 0)
    fail("{} iterations: the {} images left after iteration {} are not a multiple of the {} views of a step",
         opt_.iters, opt_.iters - start_, start_, G);
  if (opt_.save_every < 0 || opt_.save_every % G != 0)
    fail("save_every {} is not a multiple of the {} views of a step", opt_.save_every, G);
  if (opt_.save_every > 0 && opt_.out.empty())
    fail("save_every {}: checkpoints need an output folder", opt_.save_every);
  if (opt_.test_every > 0 && opt_.writer) {
    test_views_ = scene_.test_indices();
    if (test_views_.empty())
      fail("test_every: {} has no held-out views (its split puts every view in training)", scene_.root.string());
  }
  if (!opt_.writer || opt_.out.empty()) return;
  ensure_dir(opt_.out);
  if (!opt_.resumed_from.empty()) config["resumed_from"] = opt_.resumed_from;
  atomic_write_text(opt_.out / "config.json", config.dump(2) + "\n");
}

namespace {
// FOLDER/checkpoints/iter_<N>.ckpt (+ FOLDER/point_cloud_iter_<N>.ply); returns the checkpoint's name under `out`.
std::string write_snapshot(const Trainer& trainer, const fs::path& folder, const fs::path& out, bool with_ply) {
  const int it = trainer.iteration();
  ensure_dir(folder / "checkpoints");
  const std::string name = fmt::format("iter_{}.ckpt", it);
  trainer.save_checkpoint(folder / "checkpoints" / name);
  if (with_ply) write_model_ply(folder / fmt::format("point_cloud_iter_{}.ply", it), trainer.model());
  return (out / "checkpoints" / name).string();
}
}  // namespace

std::string TrainingRun::snapshot(bool with_ply) const {
  return write_snapshot(trainer_, opt_.out, opt_.out, with_ply);
}

// The held-out views' PSNR / SSIM after a step that ended at `it` images seen, with the training time so far
// (the scoring itself left out), every test_every images and at the end.
void TrainingRun::score_held_out(int it, Progress& bar, double elapsed) {
  const int G = trainer_.step_views();
  if (test_views_.empty() || !(it / opt_.test_every > (it - G) / opt_.test_every || it >= opt_.iters)) return;
  const auto ts = std::chrono::steady_clock::now();
  const ViewScore sc = score_views(scene_, test_views_, trainer_.model(), trainer_.config().white_bg,
                                   trainer_.config().near_plane, test_images_);
  const double train_s = elapsed - test_seconds_;
  test_seconds_ += std::chrono::duration<double>(std::chrono::steady_clock::now() - ts).count();
  curve_.push_back({{"iteration", it},
                    {"train_seconds", train_s},
                    {"test_psnr", sc.psnr},
                    {"test_ssim", sc.ssim},
                    {"num_gaussians", trainer_.model().n}});
  bar.note(fmt::format("test {:>7}: PSNR {:.2f} dB, SSIM {:.4f} ({} views) after {} of training", it, sc.psnr, sc.ssim,
                       test_views_.size(), format_duration(train_s)));
}

void TrainingRun::train(const StepCallback& on_step) {
  const bool progress = opt_.progress && opt_.writer;
  ms_.reserve(size_t(opt_.iters - trainer_.iteration()) / size_t(trainer_.step_views()));
  step_parts_.reserve(ms_.capacity());
  Progress bar(opt_.label, opt_.iters - start_, progress);
  const auto t0 = std::chrono::steady_clock::now();
  while (trainer_.iteration() < opt_.iters) {
    StepInfo s;
    try {
      s = trainer_.step();
    } catch (const Error& e) {  // e.g. a non-finite loss or gradient: nothing of this run's state is saved
      if (last_ckpt_.empty()) fail("{} (no checkpoint was written: --save-every N keeps one)", e.what());
      fail("{} (the last checkpoint {} is intact: --resume from it)", e.what(), last_ckpt_);
    }
    const int it = trainer_.iteration();
    ms_.push_back(float(s.ms));
    iter_.push_back(it);
    densify_ms_.push_back(float(s.times.densify));
    StepTimes::each([&](const char*, double StepTimes::*m) { parts_.*m += s.times.*m; });
    step_parts_.push_back(s.times);
    average_.add(s, ms_.size() == 1);
    const double elapsed = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    score_held_out(it, bar, elapsed);
    if (opt_.writer && opt_.save_every > 0 && it % opt_.save_every == 0 && it < opt_.iters) last_ckpt_ = snapshot(true);
    if (progress)
      bar.update(it - start_, fmt::format("loss {:.4f}{} psnr {:.2f} N {} {:.1f} ms/it", average_.loss,
                                          average_.terms_text(), average_.psnr, s.num_gaussians, s.ms));
    if (on_step && !on_step(RunStep{s, it, start_, opt_.iters, average_, elapsed})) {
      stopped_ = stop_reason_.empty() ? "callback" : stop_reason_;
      break;
    }
  }
  wall_ = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  bar.finish(fmt::format("loss {:.4f} psnr {:.2f} N {}{}", average_.loss, average_.psnr, trainer_.model().n,
                         stopped_.empty() ? "" : " (stopped: " + stopped_ + ")"));
}

json TrainingRun::stats() const {
  const size_t steps = ms_.size();
  auto median = [](auto v) {  // the upper median of a copy, 0 when empty
    std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
    return v.empty() ? 0.0 : double(v[v.size() / 2]);
  };
  const Reducer& red = trainer_.reducer();
  json stats = {{"iterations", trainer_.iteration()},
                {"iterations_this_run", trainer_.iteration() - start_},
                {"stopped", stopped_.empty() ? json(nullptr) : json(stopped_)},
                {"median_ms_per_iter", median(ms_)},
                {"mean_ms_per_iter", steps ? (wall_ - test_seconds_) * 1000.0 / double(steps) : 0.0},
                {"peak_rss_mb", peak_rss_mb()},
                {"num_gaussians", trainer_.model().n},
                {"wall_time_s", wall_},
                {"test_seconds", test_seconds_},
                {"test_curve", curve_},
                {"final_train_loss_ema", average_.loss},
                {"final_train_loss_terms_ema", average_.terms_json()},
                {"final_train_psnr_ema", average_.psnr},
                {"threads", omp_get_max_threads()},
                {"ranks", red.size()},
                {"views_per_step", trainer_.step_views()},
                {"comm_bytes_per_step", steps ? red.stats.bytes_sent / double(steps) : 0.0},
                {"comm_ms_per_step", steps ? red.stats.ms / double(steps) : 0.0}};
  // The slowest steps, where the mean departs from the median (densification, observation-table rebuilds).
  std::vector<size_t> order(steps);
  for (size_t i = 0; i < steps; ++i) order[i] = i;
  const size_t top = std::min<size_t>(5, steps);
  std::partial_sort(order.begin(), order.begin() + top, order.end(),
                    [&](size_t x, size_t y) { return ms_[x] > ms_[y]; });
  json slowest = json::array();
  for (size_t i = 0; i < top; ++i)
    slowest.push_back({{"iteration", iter_[order[i]]}, {"ms", ms_[order[i]]}, {"densify_ms", densify_ms_[order[i]]}});
  stats["slowest_steps"] = slowest;
  json part_ms = json::object();
  StepTimes::each(
      [&](const char* name, double StepTimes::*m) { part_ms[name] = steps ? parts_.*m / double(steps) : 0.0; });
  stats["mean_ms_per_part"] = part_ms;
  // The median of each part over the steps (robust to the steps a busy machine slows; the medians need not add up
  // to the median step).
  json part_median = json::object();
  std::vector<double> v(steps);
  StepTimes::each([&](const char* name, double StepTimes::*m) {
    for (size_t i = 0; i < steps; ++i) v[i] = step_parts_[i].*m;
    part_median[name] = median(v);
  });
  stats["median_ms_per_part"] = part_median;
  return stats;
}

json TrainingRun::save() const {
  json s = stats();
  if (!opt_.writer || opt_.out.empty()) return s;
  // The final files as one change of the folder (core/folder.h): a run killed while they are written leaves the
  // folder as it was (config.json, the checkpoints so far), never point_cloud.ply without train_stats.json.
  write_folder_whole(opt_.out, [&](const fs::path& tmp) {
    write_model_ply(tmp / "point_cloud.ply", trainer_.model());
    if (opt_.save_every > 0) write_snapshot(trainer_, tmp, opt_.out, false);
    atomic_write_text(tmp / "train_stats.json", s.dump(2) + "\n");
  });
  return s;
}

std::string TrainingRun::summary() const {
  const json s = stats();
  std::string t = fmt::format("trained {} iterations in {} ({:.1f} ms/it median), {} Gaussians",
                              s["iterations_this_run"].get<int>(), format_duration(wall_),
                              s["median_ms_per_iter"].get<double>(), trainer_.model().n);
  if (!opt_.out.empty()) t += " -> " + (opt_.out / "point_cloud.ply").string();
  std::string parts;  // in step order
  StepTimes::each([&](const char* name, double StepTimes::*) {
    parts += fmt::format("{}{} {:.1f}", parts.empty() ? "" : ", ", name, s["mean_ms_per_part"][name].get<double>());
  });
  t += "\nmean ms per step: " + parts;
  if (trainer_.reducer().size() > 1)
    t += fmt::format("\ngradient exchange per step (rank 0): {:.2f} MB sent, {:.1f} ms",
                     s["comm_bytes_per_step"].get<double>() / 1e6, s["comm_ms_per_step"].get<double>());
  return t;
}

}  // namespace hgs::train
