// `hgs export MODEL (--text "red mug" [--scene SCENE] | --object ID) [--remove] --out FILE.ply`: writes the
// Gaussians of the chosen object(s) (hard id z_n), or the scene without them, as a standard 3DGS PLY. With --text,
// the objects the query's answer chooses (query.h: choose_objects).
#include <fmt/format.h>

#include "cli/command.h"
#include "core/error.h"
#include "model/ply.h"
#include "query/session.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;

struct ExportArgs {
  std::string model, out, scene, clip;
  std::vector<std::string> texts;
  std::vector<int> objects;
  bool remove = false;
};

void run_export(const ExportArgs& a) {
  fs::path ply = a.model;
  if (fs::is_directory(ply)) ply /= "point_cloud.ply";
  std::vector<int> objects = a.objects;
  GaussianModel model;
  std::string names;
  if (!a.texts.empty()) {
    if (a.scene.empty()) fail("--text needs --scene SCENE (for the text embeddings and object names)");
    query::Session s(a.scene, ply, 1, a.clip);
    for (auto& t : a.texts) {
      // Every object the answer chooses (its anchor and the anchor's fragments), as `hgs query` masks them.
      const auto ans = s.ask(t);
      std::string which;
      for (int k : ans.chosen) {
        objects.push_back(k);
        float rel = 0;
        for (const auto& sc : ans.scores)
          if (sc.object == k) rel = sc.relevancy;
        which +=
            fmt::format("{}object {} ({}, relevancy {:.3f})", which.empty() ? "" : " + ", k, s.object_name(k), rel);
      }
      names += fmt::format("{}\"{}\" -> {}", names.empty() ? "" : "; ", t, which);
    }
    model = s.model();
  } else {
    if (objects.empty()) fail("give --text or --object");
    model = read_model_ply(ply);
  }
  GaussianModel out = query::select_objects(model, objects, a.remove);
  if (out.n == 0) fail("no Gaussians selected (object ids {})", fmt::join(objects, ", "));
  write_model_ply(a.out, out);
  if (!names.empty()) fmt::print("{}\n", names);
  fmt::print("wrote {} of {} Gaussians ({} object{} {}) to {}\n", out.n, model.n, a.remove ? "without" : "of",
             objects.size() > 1 ? "s" : "", fmt::join(objects, ", "), a.out);
}

CommandRegistration reg(
    {"export", "Write one object's Gaussians (or the scene without it) as a 3DGS PLY", 60, [](CLI::App& sub) {
       auto a = std::make_shared<ExportArgs>();
       sub.add_option("MODEL", a->model, "Model folder (point_cloud.ply) or PLY file")->required();
       sub.add_option("--out", a->out, "Output PLY")->required();
       sub.add_option("--text", a->texts,
                      "Select the objects the answer to this text chooses, as `hgs query` does (repeatable)");
       sub.add_option("--object", a->objects, "Select object id(s) (repeatable)");
       sub.add_option("--scene", a->scene, "Scene folder (text embeddings and names; needed with --text)");
       sub.add_option("--clip", a->clip, "OpenCLIP weights to embed the text");
       sub.add_flag("--remove", a->remove, "Write the scene without the selected object(s)");
       return [a] { run_export(*a); };
     }});

}  // namespace
}  // namespace hgs::cli
