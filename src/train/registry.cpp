// The method registry and the scene -> trainer factory (see registry.h).
#include "train/registry.h"

#include <algorithm>
#include <mutex>

#include "core/error.h"
#include "core/excerpt.h"
#include "train/train_views.h"

namespace hgs::train {
namespace {

std::mutex& registry_mutex() {
  static std::mutex m;
  return m;
}

std::vector<MethodFactory>& registry() {
  static std::vector<MethodFactory> r{
      {"rgb", "plain 3DGS", [](const Scene&, const std::vector<int>&, const TrainConfig&, const nlohmann::json&, bool) {
         return std::unique_ptr<Method>(std::make_unique<RgbMethod>());
       }}};
  return r;
}

}  // namespace

void register_method(MethodFactory f) {
  std::lock_guard<std::mutex> lock(registry_mutex());
  auto& r = registry();
  auto it = std::find_if(r.begin(), r.end(), [&](const MethodFactory& m) { return m.name == f.name; });
  if (it != r.end()) *it = std::move(f);
  else r.push_back(std::move(f));
}

std::vector<std::string> method_names() {
  std::lock_guard<std::mutex> lock(registry_mutex());
  std::vector<std::string> names;
  for (const auto& m : registry()) names.push_back(m.name);
  return names;
}

std::unique_ptr<Trainer> make_trainer(const Scene& scene, const std::vector<int>& idx, const TrainConfig& cfg,
                                      const std::string& method, const nlohmann::json& options, bool progress,
                                      Reducer* reducer) {
  MethodFactory f;
  {
    std::lock_guard<std::mutex> lock(registry_mutex());
    for (const auto& m : registry())
      if (m.name == method) f = m;
  }
  if (!f.make) {
    std::string known;
    for (const auto& n : method_names()) known += (known.empty() ? "" : ", ") + n;
    fail("unknown training method '{}' (known: {})", excerpt(method), known);
  }
  if (idx.empty()) fail("{}: the scene has no training views", scene.root.string());
  std::unique_ptr<Method> m = f.make(scene, idx, cfg, options, progress);
  auto views = load_train_views(scene, idx, progress, cfg.near_plane);
  const float extent = scene_extent(scene, idx);
  GaussianModel init = init_from_points(scene.points, scene.point_colors, cfg.sh_degree);
  return std::make_unique<Trainer>(cfg, std::move(init), std::move(views), extent, std::move(m), reducer);
}

}  // namespace hgs::train
