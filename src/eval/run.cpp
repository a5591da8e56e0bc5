// Evaluation drivers: label iteration, frame <-> view matching, timing of the callbacks, PNG output.
#include "eval/run.h"

#include <algorithm>
#include <cctype>
#include <chrono>

#include "core/error.h"
#include "core/progress.h"
#include "eval/instances.h"
#include "eval/labels.h"
#include "eval/visualize.h"

namespace hgs::eval {

namespace fs = std::filesystem;

namespace {

using Clock = std::chrono::steady_clock;
double since(Clock::time_point t0) { return std::chrono::duration<double>(Clock::now() - t0).count(); }

int view_for_label(const Scene& scene, const LerfFrameLabels& L) {
  for (auto& v : scene.views)
    if (v.stem == L.stem) return v.index;
  const std::string info_stem = fs::path(L.image_name).replace_extension().generic_string();
  for (auto& v : scene.views)
    if (v.name == L.image_name || v.stem == info_stem) return v.index;
  fail("{}: no view of the scene is named {} (label stem) or {} (info.name)", L.file.string(), L.stem, L.image_name);
}

// A callback's [H, W] output must match the view.
template <typename T>
void check_size(const std::vector<T>& v, const View& view, const std::string& what) {
  if (v.size() != size_t(view.width) * view.height)
    fail("eval: {} for view {} holds {} values, expected {}x{}", what, view.name, v.size(), view.width, view.height);
}

// Calls fn(view index, image (loaded only when PNGs are written), category) for every (frame, query) of the
// LERF-OVS labels, with a progress bar.
void for_each_lerf_query(const Scene& scene, const RunOptions& opt, const char* label,
                         const std::function<void(int, const Image&, const LerfCategory&)>& fn) {
  const auto frames = load_lerf_labels(scene.root, 0, 0, scene.downscale);
  Progress bar(label, static_cast<long>(frames.size()), opt.progress);
  for (size_t f = 0; f < frames.size(); ++f) {
    const LerfFrameLabels& L = frames[f];
    const int vi = view_for_label(scene, L);
    const View& view = scene.views[vi];
    if (L.width != view.width || L.height != view.height)
      fail("{}: label size {}x{} does not match view {} ({}x{})", L.file.string(), L.width, L.height, view.name,
           view.width, view.height);
    const Image img = opt.overlay_dir.empty() ? Image() : scene.load_image(vi);
    for (auto& cat : L.categories) fn(vi, img, cat);
    bar.update(static_cast<long>(f + 1));
  }
  bar.finish();
}

void write_pngs(const RunOptions& opt, const View& view, const Image& img, const std::string& query, const Mask& pred,
                const Mask& gt, const std::vector<float>& heat) {
  if (opt.overlay_dir.empty()) return;
  const fs::path dir = opt.overlay_dir / view.stem;
  const std::string q = safe_file_name(query);
  save_overlay_png(dir / (q + ".overlay.png"), img, pred, gt);
  save_mask_png(dir / (q + ".mask.png"), pred, view.width, view.height);
  if (!heat.empty()) save_heatmap_png(dir / (q + ".heatmap.png"), heat, view.width, view.height);
}

}  // namespace

std::string safe_file_name(const std::string& s) {
  std::string o;
  for (char c : s) o += (std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_' || c == '.') ? c : '_';
  if (o.empty() || o == "." || o == "..") o = "_" + o;
  return o;
}

LerfOptions lerf_options_for(const RunOptions& opt, int width) {
  return opt.lerf_scaled ? scaled_lerf_options(width, opt.lerf) : opt.lerf;
}

std::string scaled_lerf_rule() { return fmt::format("scaled to each image (x width / {})", kLerfReferenceWidth); }

EvalReport run_lerf_ovs(const Scene& scene, const RelevancyFn& fn, const RunOptions& opt) {
  EvalReport rep;
  rep.protocol = "lerf-ovs";
  rep.scene = scene.root.filename().string();
  rep.mode = "pixel";
  rep.extra = {{"box", opt.lerf.box}, {"threshold", opt.lerf.threshold}, {"majority", opt.lerf.majority}};
  if (opt.lerf_scaled) {  // the windows differ per image width: the rule instead of one box and majority
    rep.extra.erase("box");
    rep.extra.erase("majority");
    rep.extra["lerf_windows"] = scaled_lerf_rule();
  }
  for_each_lerf_query(scene, opt, "eval lerf-ovs", [&](int vi, const Image& img, const LerfCategory& cat) {
    const View& view = scene.views[vi];
    const auto t0 = Clock::now();
    const std::vector<float> rel = fn(vi, cat.name);
    check_size(rel, view, "relevancy map of \"" + cat.name + "\"");
    const LerfQueryResult r = evaluate_lerf_query(rel, view.width, view.height, cat, lerf_options_for(opt, view.width));
    rep.records.push_back(lerf_record(view.name, cat.name, r, since(t0)));
    write_pngs(opt, view, img, cat.name, r.post.mask, cat.mask, rel);
  });
  return rep;
}

EvalReport run_lerf_ovs_masks(const Scene& scene, const MaskFn& fn, const RunOptions& opt) {
  EvalReport rep;
  rep.protocol = "lerf-ovs";
  rep.scene = scene.root.filename().string();
  rep.mode = "object";
  for_each_lerf_query(scene, opt, "eval lerf-ovs (object)", [&](int vi, const Image& img, const LerfCategory& cat) {
    const View& view = scene.views[vi];
    const auto t0 = Clock::now();
    std::vector<float> heat;
    const Mask pred = fn(vi, cat.name, &heat);
    check_size(pred, view, "predicted mask of \"" + cat.name + "\"");
    const double secs = since(t0);
    const MaskScores s = score_mask(cat.mask, pred, view.width, view.height, opt.lerf.boundary_d);
    rep.records.push_back({view.name, cat.name, s.iou, s.biou, s.acc, -1, secs});
    write_pngs(opt, view, img, cat.name, pred, cat.mask, heat);
  });
  return rep;
}

EvalReport run_3dovs(const Scene& scene, const ClassRelevancyFn& fn, const RunOptions& opt) {
  const OvsLabelSet labels = open_3dovs_labels(scene.root);
  EvalReport rep;
  rep.protocol = opt.ovs_scoring == OvsScoring::LabelledOnly ? "3d-ovs-labelled" : "3d-ovs";
  rep.scene = scene.root.filename().string();
  rep.mode = "pixel";
  rep.extra = {{"classes", labels.classes}};
  Progress bar("eval 3d-ovs", static_cast<long>(labels.views.size()), opt.progress);
  double pairs = 0, best = 0;  // (frame, class) pairs, and the sum of their best scores (ovs_ceiling)
  for (size_t i = 0; i < labels.views.size(); ++i) {
    const int vi = labels.views[i].index;
    if (vi < 0 || vi >= static_cast<int>(scene.views.size()))
      fail("{}: view index {} is out of range (the scene has {} views)", labels.views[i].dir.string(), vi,
           scene.views.size());
    const View& view = scene.views[vi];
    const OvsViewLabels gt = load_3dovs_view(labels, i, view.width, view.height, scene.downscale);
    const auto t0 = Clock::now();
    auto rel = fn(vi, labels.classes);
    if (rel.size() != labels.classes.size())
      fail("eval: {} class relevancy maps for view {}, expected {}", rel.size(), view.name, labels.classes.size());
    for (size_t c = 0; c < rel.size(); ++c) check_size(rel[c], view, "relevancy map of \"" + labels.classes[c] + "\"");
    OvsImageResult r =
        evaluate_3dovs_image(rel, gt.masks, view.width, view.height, opt.lerf.boundary_d, opt.ovs_scoring);
    const double secs = since(t0);
    pairs += double(gt.masks.size());
    best += r.ceiling * double(gt.masks.size());
    const size_t first = rep.records.size();
    add_3dovs_image(rep, view.name, labels.classes, r);
    for (size_t k = first; k < rep.records.size(); ++k) rep.records[k].seconds = secs / double(labels.classes.size());
    if (!opt.overlay_dir.empty()) {
      const Image img = scene.load_image(vi);
      save_png(opt.overlay_dir / view.stem / "classes.png", class_overlay(img, r.prediction));
      for (size_t c = 0; c < labels.classes.size(); ++c) {
        Mask pred(r.prediction.size());
        for (size_t p = 0; p < pred.size(); ++p) pred[p] = r.prediction[p] == c;
        write_pngs(opt, view, img, labels.classes[c], pred, gt.masks[c], rel[c]);
      }
    }
    bar.update(static_cast<long>(i + 1));
  }
  bar.finish();
  // The protocol scores a class absent from a frame's ground truth 0 whatever is predicted, and gives every
  // unlabelled pixel some class: the best mIoU any prediction can reach is the mean of the frames' ceilings.
  if (pairs > 0 && opt.ovs_scoring == OvsScoring::Protocol) rep.extra["miou_ceiling"] = best / pairs;
  return rep;
}

EvalReport run_instances(const Scene& scene, const MaskFn& fn, const RunOptions& opt) {
  const auto names = load_object_names(scene.root);
  const auto test = scene.test_indices();
  if (test.empty()) fail("{}: the scene has no test views", scene.root.string());
  EvalReport rep;
  rep.protocol = "instances";
  rep.scene = scene.root.filename().string();
  rep.mode = "object";
  // Where the objects' names come from: gt/objects.json, or masks/objects.json for a scene without it.
  rep.extra = {{"object_names", fs::relative(object_names_file(scene.root), scene.root).generic_string()}};
  // The phrases asked: every object's name, or a query set of gt/queries.json.
  std::vector<std::pair<std::string, int>> queries;
  if (opt.query_set.empty()) {
    for (const auto& [id, name] : names) queries.emplace_back(name, id);
  } else {
    queries = load_query_set(scene.root, opt.query_set, names);
    rep.extra["query_set"] = opt.query_set;
  }
  Progress bar("eval instances", static_cast<long>(test.size()), opt.progress);
  for (size_t i = 0; i < test.size(); ++i) {
    const View& view = scene.views[test[i]];
    const InstanceLabels gt =
        load_instance_masks(scene.root, view.name, names, view.width, view.height, scene.downscale);
    const Image img = opt.overlay_dir.empty() ? Image() : scene.load_image(view.index);
    for (size_t k = 0; k < gt.ids.size(); ++k) {
      bool visible = false;
      for (auto v : gt.masks[k]) visible |= v != 0;
      if (!visible) continue;
      for (const auto& [phrase, id] : queries) {
        if (id != gt.ids[k]) continue;
        const auto t0 = Clock::now();
        std::vector<float> heat;
        Mask pred = fn(view.index, phrase, &heat);
        check_size(pred, view, "predicted mask of \"" + phrase + "\"");
        const double secs = since(t0);
        MaskScores s = score_mask(gt.masks[k], pred, view.width, view.height, opt.lerf.boundary_d);
        rep.records.push_back({view.name, phrase, s.iou, s.biou, s.acc, -1, secs});
        write_pngs(opt, view, img, phrase, pred, gt.masks[k], heat);
      }
    }
    bar.update(static_cast<long>(i + 1));
  }
  bar.finish();
  return rep;
}

}  // namespace hgs::eval
