// Trainer checkpoints: `hgs train SCENE --resume FILE [--method rgb|hybrid]` -> make_trainer ->
// Trainer::load_checkpoint. A fresh trainer per input and method, on the tiny scene, configured as
// `hgs train --iters 20 --sh-degree 0 --threads 1` (how fuzz/make_corpus writes the seed checkpoints).
#include <memory>

#include "core/error.h"
#include "fuzz.h"
#include "hybrid/config.h"
#include "hybrid/register.h"
#include "scene/scene.h"
#include "train/registry.h"

HGS_FUZZ_TARGET(checkpoint) {
  static const auto dir = hgs::fuzz::scratch("checkpoint");
  static const hgs::Scene scene = [] {
    hgs::hybrid::register_method();
    return hgs::load_scene(hgs::fuzz::tiny_scene());
  }();
  const auto file = dir / "iter.ckpt";
  hgs::fuzz::put_file(file, {reinterpret_cast<const char*>(data), size});
  for (const char* method : {"rgb", "hybrid"}) {
    hgs::train::TrainConfig base;
    base.sh_degree = 0;
    hgs::train::TrainConfig cfg = base.scaled_to(20);
    cfg.method = method;
    const nlohmann::json options =
        std::string(method) == "hybrid" ? hgs::hybrid::HybridConfig{}.to_json() : nlohmann::json();
    auto trainer = hgs::train::make_trainer(scene, scene.train_indices(), cfg, method, options, false);
    try {
      trainer->load_checkpoint(file);
    } catch (const hgs::Error&) {
    }
  }
  return 0;
}
