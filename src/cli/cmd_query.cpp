// `hgs query SCENE MODEL --text "red mug" [--text ...] [--view NAME | --split test|train|all] --out DIR`:
// answers text queries on a trained hybrid model and writes, per view and query, the mask, an overlay and a
// heatmap PNG, plus result.json (chosen objects, scores, timings).
#include <fmt/format.h>

#include <chrono>
#include <nlohmann/json.hpp>

#include "cli/command.h"
#include "core/error.h"
#include "core/excerpt.h"
#include "core/fs.h"
#include "core/progress.h"
#include "eval/run.h"
#include "eval/visualize.h"
#include "query/session.h"

namespace hgs::cli {
namespace {
namespace fs = std::filesystem;

struct QueryArgs {
  std::string scene, model, out, view, split = "test", mode = "object", clip;
  std::vector<std::string> texts;
  int downscale = 1, threads = 0;
  float min_relevancy = 0, mask_threshold = 0.5f, fragment_margin = query::kFragmentMargin, anchor_support = 0;
  bool quiet = false;
};

double since(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

fs::path model_ply(const std::string& model) {
  fs::path p = model;
  if (fs::is_directory(p)) p /= "point_cloud.ply";
  return p;
}

std::vector<int> pick_views(const Scene& s, const std::string& view, const std::string& split) {
  if (!view.empty()) {
    for (auto& v : s.views)
      if (v.name == view || v.stem == view) return {v.index};
    fail("--view {}: no such view in {}", excerpt(view), s.root.string());
  }
  if (split == "test") return s.test_indices();
  if (split == "train") return s.train_indices();
  std::vector<int> all;
  for (auto& v : s.views) all.push_back(v.index);
  return all;
}

void run_query(const QueryArgs& a) {
  set_threads(a.threads);
  auto t0 = std::chrono::steady_clock::now();
  query::Session session(a.scene, model_ply(a.model), a.downscale, a.clip);
  const double load_s = since(t0);
  const Scene& scene = session.scene();
  std::vector<int> views = pick_views(scene, a.view, a.split);
  if (views.empty()) fail("--split {}: the scene has no such views", excerpt(a.split));
  query::QueryOptions qo{a.min_relevancy, a.mask_threshold, a.fragment_margin, a.anchor_support};
  nlohmann::json result = {{"scene", fs::absolute(a.scene).lexically_normal().string()},
                           {"model", model_ply(a.model).string()},
                           {"mode", a.mode},
                           {"text_source", session.text().source()},
                           {"load_seconds", load_s},
                           {"queries", nlohmann::json::array()}};
  ensure_dir(a.out);
  Progress bar("query", long(views.size() * a.texts.size()), !a.quiet);
  long done = 0;
  for (const std::string& text : a.texts) {
    auto tq = std::chrono::steady_clock::now();
    nlohmann::json q = {{"text", text}};
    query::ObjectAnswer ans;
    if (a.mode == "object") {
      ans = session.ask(text, qo);
      nlohmann::json scores = nlohmann::json::array();
      for (auto& s : ans.scores)
        scores.push_back({{"object", s.object},
                          {"name", session.object_name(s.object)},
                          {"relevancy", s.relevancy},
                          {"cosine", s.cosine}});
      nlohmann::json chosen = nlohmann::json::array();
      for (int k : ans.chosen) chosen.push_back({{"object", k}, {"name", session.object_name(k)}});
      q["scores"] = scores;
      q["chosen"] = chosen;
    }
    const double select_s = since(tq);
    nlohmann::json outputs = nlohmann::json::array();
    double render_s = 0;
    for (int vi : views) {
      const View& v = scene.views[vi];
      auto tr = std::chrono::steady_clock::now();
      std::vector<float> heat;
      eval::Mask mask;
      if (a.mode == "object") {
        mask = session.object_mask(vi, ans.chosen, a.mask_threshold, &heat);
      } else {
        heat = session.pixel_relevancy(vi, text);
        mask = eval::lerf_postprocess(heat, v.width, v.height).mask;
      }
      render_s += since(tr);
      const fs::path dir = fs::path(a.out) / v.stem;
      const std::string base = eval::safe_file_name(text);
      Image img = scene.load_image(vi);
      eval::save_mask_png(dir / (base + ".mask.png"), mask, v.width, v.height);
      eval::save_overlay_png(dir / (base + ".overlay.png"), img, mask, {});
      eval::save_heatmap_png(dir / (base + ".heatmap.png"), heat, v.width, v.height, 0.f,
                             a.mode == "object" ? 1.f : 0.f);
      size_t area = 0;
      for (auto m : mask) area += m != 0;
      outputs.push_back(
          {{"view", v.name}, {"mask_pixels", area}, {"overlay", (dir / (base + ".overlay.png")).string()}});
      bar.update(++done);
    }
    q["views"] = outputs;
    q["seconds"] = {{"select", select_s}, {"render", render_s}, {"per_view", render_s / views.size()}};
    result["queries"].push_back(q);
  }
  bar.finish();
  atomic_write_text(fs::path(a.out) / "result.json", result.dump(2) + "\n");
  for (auto& q : result["queries"]) {
    if (a.mode == "object" && !q["chosen"].empty()) {
      const int k = q["chosen"][0]["object"].get<int>();  // the anchor (query.h: choose_objects)
      float rel = 0;
      for (const auto& sc : q["scores"])
        if (sc["object"].get<int>() == k) rel = sc["relevancy"].get<float>();
      fmt::print("\"{}\" -> object {} ({}), relevancy {:.3f}\n", q["text"].get<std::string>(), k,
                 q["chosen"][0]["name"].get<std::string>(), rel);
    }
  }
  fmt::print("wrote masks, overlays and heatmaps for {} view(s) to {}/ (result.json)\n", views.size(), a.out);
}

CommandRegistration reg(
    {"query", "Answer text queries on a trained hybrid model: masks, overlays, heatmaps per view", 40,
     [](CLI::App& sub) {
       auto a = std::make_shared<QueryArgs>();
       sub.add_option("SCENE", a->scene, "Scene folder")->required();
       sub.add_option("MODEL", a->model, "Model folder (point_cloud.ply) or PLY file")->required();
       sub.add_option("--text", a->texts, "Query text (repeatable)")->required();
       sub.add_option("--out", a->out, "Output folder")->required();
       sub.add_option("--view", a->view, "Only this view (image name or stem)");
       sub.add_option("--split", a->split, "Views to render: test, train or all")
           ->check(CLI::IsMember({"test", "train", "all"}))
           ->capture_default_str();
       sub.add_option("--mode", a->mode, "object (hybrid, default) or pixel (LERF-style relevancy map)")
           ->check(CLI::IsMember({"object", "pixel"}))
           ->capture_default_str();
       sub.add_option("--min-relevancy", a->min_relevancy,
                      "Object mode: also choose every object with relevancy >= this (0 = best only)")
           ->capture_default_str();
       sub.add_option("--mask-threshold", a->mask_threshold, "Object mode: mask = rendered object opacity > this")
           ->capture_default_str();
       sub.add_option("--fragment-margin", a->fragment_margin,
                      "Object mode: also choose every label within this cosine of the anchor whose Gaussians lie "
                      "where its Gaussians lie (the fragments SAM2 leaves of one object: a re-born track, a part; a "
                      "rule of hgs, query/fragments.h); 0 = the anchor alone (the best label that holds Gaussians)")
           ->check(CLI::Range(0.0, 2.0))
           ->capture_default_str();
       sub.add_option("--anchor-support", a->anchor_support,
                      "Object mode: the anchor must render, over the training views, at least this fraction of the "
                      "pixels its mask id covers in their masks (a rule of hgs, off by default; query/session.h); "
                      "0 = off; 0.25 was chosen on the development seeds (docs/ablation.md)")
           ->check(CLI::Range(0.0, 1.0))
           ->capture_default_str();
       sub.add_option("--clip", a->clip,
                      "OpenCLIP weights (.safetensors) to embed the text (else SCENE/text_embeddings.json)");
       sub.add_option("--downscale", a->downscale, "Integer image downscale (as used for training)")
           ->check(CLI::Range(1, 64));
       add_threads_option(sub, a->threads);
       sub.add_flag("--quiet", a->quiet, "No progress bar");
       return [a] { run_query(*a); };
     }});

}  // namespace
}  // namespace hgs::cli
