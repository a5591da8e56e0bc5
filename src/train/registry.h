// Training methods by name. `hgs train --method NAME` (and `hgs ablate`, the tests, the diagnostics) build their
// trainer here: make_trainer loads the scene's training views, initialises Gaussians from its SfM points and
// plugs in the named method, built by the factory the method registered from its options (JSON: the method's
// own configuration, null = its defaults). Plain 3DGS ("rgb") is always there; methods above train/ register
// themselves (hybrid::register_method()), so train/ never includes them.
#pragma once
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "scene/scene.h"
#include "train/trainer.h"

namespace hgs::train {

struct MethodFactory {
  std::string name;  // --method value
  std::string help;  // one line for --help and errors
  // Builds the method for the training views `idx` of `scene` (it may load its own per-view data).
  std::function<std::unique_ptr<Method>(const Scene& scene, const std::vector<int>& idx, const TrainConfig& cfg,
                                        const nlohmann::json& options, bool progress)>
      make;
};

// Adds (or replaces) a method.
void register_method(MethodFactory f);
// Registered names, "rgb" first.
std::vector<std::string> method_names();
// The trainer for `method` on the training views `idx`; throws hgs::Error for an unknown method or no views.
// reducer: see Trainer (null = one process).
std::unique_ptr<Trainer> make_trainer(const Scene& scene, const std::vector<int>& idx, const TrainConfig& cfg,
                                      const std::string& method, const nlohmann::json& options, bool progress,
                                      Reducer* reducer = nullptr);

}  // namespace hgs::train
