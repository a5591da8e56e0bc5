// hgs.Trainer: the library's train::Trainer (make_trainer: training views, SfM initialisation, the method by name)
// for Python. run() is the library's training run (train/run.h), the same loop, checkpoints, statistics and model
// folder as `hgs train`, calling back into Python after every step (hgs.train's callback, progress bar and Ctrl-C,
// python/hgs/__init__.py), so a KeyboardInterrupt lands between two steps; step() runs one step alone. Options: the
// keys of TrainConfig::to_json and, for method "hybrid", of HybridConfig::to_json (docs/python.md); unknown keys and
// wrong types are hgs.Error.
#include <atomic>
#include <limits>
#include <mutex>
#include <optional>
#include <set>
#include <thread>

#include <omp.h>
#include <nlohmann/json.hpp>

#include "clip/model.h"
#include "common.h"
#include "core/error.h"
#include "core/excerpt.h"
#include "core/process.h"
#include "core/threads.h"
#include "hybrid/config.h"
#include "hybrid/register.h"
#include "nn/thread_pool.h"
#include "train/registry.h"
#include "train/run.h"
#include "train/trainer.h"

namespace hgs::py {
namespace {

using json = nlohmann::json;

// A Python scalar option as JSON (bool before int: bool is an int in Python).
json option_json(const std::string& key, pb::handle v) {
  if (pb::isinstance<pb::bool_>(v)) return v.cast<bool>();
  if (pb::isinstance<pb::int_>(v)) return v.cast<long long>();
  if (pb::isinstance<pb::float_>(v)) return v.cast<double>();
  if (pb::isinstance<pb::str>(v)) return v.cast<std::string>();
  fail("hgs.train: option '{}' must be a bool, int, float or str, got {}", excerpt(key),
       std::string(pb::str(v.get_type().attr("__name__"))));
}

// The option names of both configurations, sorted, for the message of an unknown one.
std::string key_list(const json& a, const json& b) {
  std::set<std::string> keys;
  for (const json* j : {&a, &b})
    for (auto it = j->begin(); it != j->end(); ++it)
      if (it.key() != "method" && it.key() != "iters") keys.insert(it.key());
  std::string t;
  for (const auto& k : keys) t += (t.empty() ? "" : ", ") + k;
  return t;
}

// One call at a time on a trainer (a step from two threads crashed, SIGSEGV / SIGABRT, or saw a spurious
// non-finite gradient). Calls that change the trainer (step, run, finish, load_checkpoint) are refused while
// another one runs: `Trainer.<call>: already running in another thread (Trainer.<running>)`. Calls that read it
// (model, iteration, save_checkpoint) wait for the running step, the GIL released; from run()'s own on_step they
// go ahead (between two steps; only step / run / finish / load_checkpoint are refused there), and are refused while
// run() holds the trainer in another thread.
class TrainerGuard {
 public:
  class Held {
   public:
    explicit Held(TrainerGuard* g) : g_(g) {}
    Held(Held&& o) noexcept : g_(std::exchange(o.g_, nullptr)) {}
    ~Held() {
      if (!g_) return;
      g_->owner_ = std::thread::id();
      g_->running_ = nullptr;
      g_->m_.unlock();
    }

   private:
    TrainerGuard* g_;
  };

  // For calls that change the trainer: the guard, or hgs::Error when it is held.
  Held exclusive(const char* call) {
    if (owner_ == std::this_thread::get_id())  // checked first: try_lock by the owning thread is undefined
      fail("Trainer.{}: not allowed inside Trainer.run's on_step (the run steps the trainer itself)", call);
    if (!m_.try_lock()) {
      fail("Trainer.{}: already running in another thread (Trainer.{}); a trainer takes one call at a time", call,
           running_.load() ? running_.load() : "?");
    }
    owner_ = std::this_thread::get_id();
    running_ = call;
    return Held(this);
  }
  // For calls that only read it: waits for a running step (the GIL released); goes ahead in the thread that holds
  // it (run()'s on_step, between two steps); refused while run() holds it in another thread (it holds it for the
  // whole run, and waiting could deadlock an on_step that waits for this thread).
  std::optional<std::unique_lock<std::mutex>> shared(const char* call) {
    if (owner_ == std::this_thread::get_id()) return std::nullopt;
    std::unique_lock<std::mutex> l(m_, std::defer_lock);
    if (!l.try_lock()) {
      const char* running = running_.load();
      if (running && std::string(running) == "run")
        fail("Trainer.{}: Trainer.run is running in another thread; read the trainer from its on_step", call);
      pb::gil_scoped_release nogil;
      l.lock();
    }
    return l;
  }

 private:
  std::mutex m_;
  std::atomic<std::thread::id> owner_{};
  std::atomic<const char*> running_{nullptr};
};

class PyTrainer {
 public:
  PyTrainer(std::shared_ptr<Scene> scene, const std::string& method, int iters, const pb::dict& options, bool progress)
      : scene_(std::move(scene)) {
    if (iters < 1) fail("hgs.train: iters must be >= 1, got {}", iters);
    train::TrainConfig base;
    json tj = base.scaled_to(iters).to_json();
    json hj = hybrid::HybridConfig().to_json();
    for (auto [k, v] : options) {
      const std::string key = key_arg(k, "Trainer", "options keys");
      const bool in_train = tj.contains(key) && key != "method" && key != "iters";
      const bool in_hybrid = method == "hybrid" && hj.contains(key);
      if (!in_train && !in_hybrid)
        fail("hgs.train: unknown option '{}' for method '{}' (options: {})", excerpt(key), excerpt(method),
             key_list(tj, method == "hybrid" ? hj : json::object()));
      if (in_train) tj[key] = option_json(key, v);
      if (in_hybrid) hj[key] = option_json(key, v);
    }
    tj["method"] = method;
    train::TrainConfig cfg = train::TrainConfig::from_json(tj, "hgs.train options");
    json method_options;  // null for methods without options (rgb)
    if (method == "hybrid") {
      try {
        method_options = hybrid::HybridConfig::from_json(hj).to_json();
      } catch (const json::exception& e) {
        fail("hgs.train options: a hybrid option has the wrong type ({})", e.what());
      }
    }
    const std::vector<int> idx = scene_->train_indices();
    if (idx.empty()) fail("{}: the scene has no training views", scene_->root.string());
    if (cfg.batch > int(idx.size()))
      fail("{}: a step of {} views is more than the {} training views", scene_->root.string(), cfg.batch, idx.size());
    {
      pb::gil_scoped_release nogil;
      trainer_ = train::make_trainer(*scene_, idx, cfg, method, method_options, progress);
    }
    config_ = train::run_config(*trainer_, *scene_, method_options, trainer_->model().n);
  }

  // One step; refused once the run's `iters` images are seen (the schedule ends there: learning rates, densification).
  train::StepInfo step() {
    auto held = guard_.exclusive("step");
    live();
    if (trainer_->iteration() >= trainer_->config().iters)
      fail("Trainer.step: the run's {} images are done (iters={}); finish() returns the model", trainer_->iteration(),
           trainer_->config().iters);
    pb::gil_scoped_release nogil;
    return trainer_->step();
  }
  int iteration() {
    auto held = guard_.shared("iteration");
    return live().iteration();
  }
  int step_views() {
    auto held = guard_.shared("step_views");
    return live().step_views();
  }
  int iters() {
    auto held = guard_.shared("iters");
    return live().config().iters;
  }
  // Both carry the run's near plane as the model's near_plane attribute (hgs.render and QuerySession cull at it).
  pb::object model_copy() {
    auto held = guard_.shared("model");
    live();
    return model_with_near_plane(std::make_shared<GaussianModel>(trainer_->model()), trainer_->config().near_plane);
  }
  // Ends training: the model moves out (no copy) and the trainer is released.
  pb::object finish() {
    auto held = guard_.exclusive("finish");
    live();
    const float near_plane = trainer_->config().near_plane;
    auto m = std::make_shared<GaussianModel>(std::move(trainer_->model()));
    {
      pb::gil_scoped_release nogil;
      trainer_.reset();
    }
    return model_with_near_plane(std::move(m), near_plane);
  }
  std::string config_text() const { return config_.dump(); }

  // The library's training run (train/run.h) to `iters` images: `on_step(step, iteration, loss_average)` is
  // called with the GIL after every step and ends the run when it returns False; a KeyboardInterrupt (Ctrl-C,
  // raised while on_step runs or pending when it is due) ends it as "interrupted". With `out` the run writes the
  // model folder (config.json first; checkpoints every save_every images; point_cloud.ply and train_stats.json
  // at the end, also after a stop). Another exception from on_step ends the run, writes nothing more and is
  // raised again. Returns train_stats.json's text.
  std::string run(int iters, const std::string& out, int save_every, int test_every, const std::string& resumed_from,
                  pb::object on_step) {
    auto held = guard_.exclusive("run");
    live();
    train::RunOptions ro;
    ro.out = out;
    ro.iters = iters;
    ro.save_every = save_every;
    ro.test_every = test_every;
    ro.resumed_from = resumed_from;
    std::optional<train::TrainingRun> run;
    std::optional<pb::error_already_set> raised;
    {
      pb::gil_scoped_release nogil;
      run.emplace(*trainer_, *scene_, ro, config_);
      run->train([&](const train::RunStep& s) {
        pb::gil_scoped_acquire gil;
        try {
          if (PyErr_CheckSignals() != 0) throw pb::error_already_set();
          // Only False ends the run, as hgs.train's callback (None, a forgotten return, goes on).
          if (!on_step.is_none() && on_step(s.step, s.iteration, s.average.loss).ptr() == Py_False) return false;
          if (PyErr_CheckSignals() != 0) throw pb::error_already_set();
          return true;
        } catch (pb::error_already_set& e) {
          if (e.matches(PyExc_KeyboardInterrupt)) run->stop_reason("interrupted");
          else raised.emplace(std::move(e));
          return false;
        }
      });
      if (!raised) run->save();
    }
    if (raised) throw std::move(*raised);
    return run->stats().dump();
  }
  void save_checkpoint(const std::filesystem::path& p) {
    auto held = guard_.shared("save_checkpoint");
    live();
    pb::gil_scoped_release nogil;
    trainer_->save_checkpoint(p);
  }
  void load_checkpoint(const std::filesystem::path& p) {
    auto held = guard_.exclusive("load_checkpoint");
    live();
    pb::gil_scoped_release nogil;
    trainer_->load_checkpoint(p);
  }

 private:
  std::shared_ptr<Scene> scene_;  // the trainer's views and method data came from it
  std::unique_ptr<train::Trainer> trainer_;
  json config_;
  TrainerGuard guard_;
  // The trainer, or hgs.Error once finish() has taken the model.
  train::Trainer& live() const {
    if (!trainer_) fail("hgs.Trainer: training has finished (finish() took the model)");
    return *trainer_;
  }
};

}  // namespace

void bind_train(pb::module_& m) {
  hybrid::register_method();
  // The default thread count, as the hgs command sets it (cli/main.cpp): the CPUs this process may use.
  if (!std::getenv("OMP_NUM_THREADS")) nn::set_num_threads(available_cpus());
  else if (omp_get_max_threads() > max_threads())  // the import fails with this line (100000 crashed in libgomp)
    fail("OMP_NUM_THREADS: must be {}, got {}", threads_range_text(), omp_get_max_threads());
  m.def(
      "set_threads",
      [](pb::handle n) {
        const long long v = int_arg(n, "set_threads", "n");  // int, numpy integers; TypeError otherwise
        nn::set_num_threads(checked_threads(v, "set_threads: n"));
      },
      pb::arg("n"),
      "Worker threads of OpenMP, the element-wise pool and OpenBLAS: n in 1..max_threads() (4x the hardware threads; "
      "the bound of every command's --threads), else hgs.Error (TypeError for a non-int). The default is every CPU "
      "this process may use");
  m.def("max_threads", &max_threads, "The most threads set_threads (and --threads) accept: 4x the hardware threads");
  m.def("method_names", &train::method_names, "Registered training methods ('rgb', 'hybrid')");

  pb::class_<train::StepInfo>(m, "StepInfo", "What one training step reports")
      .def_readonly("loss", &train::StepInfo::total, "The optimised objective: the sum of the weighted terms")
      .def_property_readonly(
          "terms",
          [](const train::StepInfo& s) {
            pb::dict d;
            for (const auto& t : s.terms) d[pb::str(t.name)] = t.weighted();
            return d;
          },
          "Weighted loss terms by name (rgb, app, bro, sem); they sum to loss")
      .def_readonly("psnr", &train::StepInfo::psnr, "PSNR of the step's training views")
      .def_readonly("num_gaussians", &train::StepInfo::num_gaussians)
      .def_readonly("ms", &train::StepInfo::ms, "Wall time of the step in ms")
      .def_readonly("densified", &train::StepInfo::densified)
      .def_property_readonly(
          "times",
          [](const train::StepInfo& s) {
            pb::dict d;
            train::StepTimes::each([&](const char* name, double train::StepTimes::*p) { d[name] = s.times.*p; });
            return d;
          },
          "Wall time of the step's parts in ms (prepare, forward, loss, ...)");

  pb::class_<PyTrainer>(m, "Trainer",
                        "A training run, one step at a time (hgs.train drives it: callback, progress, Ctrl-C)")
      .def(pb::init([](pb::object scene, pb::object method, pb::object iters, pb::object options, bool progress) {
             auto sc = object_arg<Scene>(scene, "Trainer", "scene", "an hgs.Scene");
             if (!pb::isinstance<pb::str>(method)) wrong_type("Trainer", "method", "a str", method);
             const long long it = int_arg(iters, "Trainer", "iters");
             if (it < 1 || it > std::numeric_limits<int>::max()) fail("hgs.train: iters must be >= 1, got {}", it);
             if (!pb::isinstance<pb::dict>(options)) wrong_type("Trainer", "options", "a dict", options);
             return std::make_unique<PyTrainer>(std::move(sc), method.cast<std::string>(), int(it),
                                                pb::reinterpret_borrow<pb::dict>(options), progress);
           }),
           pb::arg("scene"), pb::arg("method") = "hybrid", pb::arg("iters") = 30000, pb::arg("options") = pb::dict(),
           pb::arg("progress") = false,
           "Loads the training views, initialises Gaussians from the SfM points and builds the method; "
           "`iters` scales the 30k schedule (densification) as `hgs train --iters` does")
      .def("step", &PyTrainer::step,
           "One training step (G views; the GIL is released while it runs). hgs.Error once `iters` images are seen "
           "(the schedule ends there), and while another thread is in a call that changes this trainer (step, run, "
           "finish, load_checkpoint): one call at a time")
      .def_property_readonly("iteration", &PyTrainer::iteration, "Training images seen so far")
      .def_property_readonly("step_views", &PyTrainer::step_views, "Views per step (batch)")
      .def_property_readonly("iters", &PyTrainer::iters, "Images to see in the whole run")
      .def_property_readonly("model", &PyTrainer::model_copy, "A copy of the model as it is now")
      .def("finish", &PyTrainer::finish, "Ends training and returns the model (moved out, not copied)")
      .def_property_readonly("config_json", &PyTrainer::config_text, "The run's configuration as JSON text")
      .def("run", &PyTrainer::run, pb::arg("iters"), pb::arg("out") = "", pb::arg("save_every") = 0,
           pb::arg("test_every") = 0, pb::arg("resumed_from") = "", pb::arg("on_step") = pb::none(),
           "The training run to `iters` images (train/run.h; hgs.train drives it): on_step(step, iteration, "
           "loss_average) after every step, returning False ends it (None goes on); writes the model folder `out`; "
           "returns "
           "train_stats.json's text")
      .def("save_checkpoint", &PyTrainer::save_checkpoint, pb::arg("path"))
      .def("load_checkpoint", &PyTrainer::load_checkpoint, pb::arg("path"));
}

}  // namespace hgs::py
