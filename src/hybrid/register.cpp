// The hybrid method's entry in the training-method registry (see register.h).
#include "hybrid/register.h"

#include "hybrid/data.h"
#include "hybrid/method.h"
#include "train/registry.h"

namespace hgs::hybrid {

void register_method() {
  train::register_method(
      {"hybrid", "Hybrid Gaussians: object identities and language embeddings",
       [](const Scene& scene, const std::vector<int>& idx, const train::TrainConfig& cfg, const nlohmann::json& options,
          bool progress) {
         const HybridConfig hc = options.is_null() ? HybridConfig{} : HybridConfig::from_json(options);
         return std::unique_ptr<train::Method>(
             std::make_unique<HybridMethod>(hc, load_hybrid_data(scene, idx, hc, progress), cfg.seed));
       }});
}

}  // namespace hgs::hybrid
