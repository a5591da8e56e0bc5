// Evaluation drivers: walk a scene's labels, ask a callback for the method's output on each (view, query),
// score it with the protocol and collect an EvalReport; optionally write overlay / heatmap / mask PNGs.
// The callbacks hide the model: `hgs eval` renders a trained model in them, the tests use 2D features.
//
// Frames: LERF-OVS label files are matched to views by stem (label/frame_00009.json <-> the view whose
// name without extension is frame_00009), falling back to info.name; 3D-OVS folders by view index in the
// name-sorted view list; `instances` uses the test views and every object of gt/objects.json (masks/objects.json
// for a scene without it; the report's extra.object_names says which) visible in the view (objects absent from a
// view are not queried, as in LERF-OVS). Labels are loaded at the scene's
// downscale and must match the view size.
//
// PNG output (when overlay_dir is set), per frame stem and query (query names sanitised for file names):
//   <overlay_dir>/<stem>/<query>.overlay.png   image + predicted mask (red) + ground-truth contour (green)
//   <overlay_dir>/<stem>/<query>.heatmap.png   relevancy, turbo colour map over the map's own range
//   <overlay_dir>/<stem>/<query>.mask.png      predicted mask
//   3D-OVS: <overlay_dir>/<stem>/classes.png   image blended with the predicted class colours
#pragma once
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "eval/protocols.h"
#include "eval/report.h"
#include "scene/scene.h"

namespace hgs::eval {

struct RunOptions {
  LerfOptions lerf;                               // LERF-OVS post-processing; lerf.boundary_d also sets d elsewhere
  std::filesystem::path overlay_dir;              // empty: no PNGs
  OvsScoring ovs_scoring = OvsScoring::Protocol;  // 3D-OVS: the protocol's scoring or labelled pixels only
  bool lerf_scaled = false;  // LERF-OVS pixel mode: lerf's windows scaled to each image (scaled_lerf_options)
  bool progress = true;
  // instances: the phrases asked, a set of SCENE/gt/queries.json (names, synonyms, hypernyms, attributes; each
  // phrase scored against its object); empty = every object's name.
  std::string query_set;
};

// Relevancy map [H, W] of `query` on scene.views[view] (at the view's resolution).
using RelevancyFn = std::function<std::vector<float>(int view, const std::string& query)>;
// Predicted mask [H, W] of `query` on scene.views[view] (object-level mode). If `heatmap` is non-null the
// callback may fill it ([H, W]) for the heatmap PNG.
using MaskFn = std::function<Mask(int view, const std::string& query, std::vector<float>* heatmap)>;
// Relevancy maps [C][H, W] of every class on scene.views[view]; argmax over classes is the prediction.
using ClassRelevancyFn =
    std::function<std::vector<std::vector<float>>(int view, const std::vector<std::string>& classes)>;

// The LERF post-processing options for an image `width` pixels wide: opt.lerf, scaled when opt.lerf_scaled.
LerfOptions lerf_options_for(const RunOptions& opt, int width);
// How a report names scaled windows (its extra.lerf_windows).
std::string scaled_lerf_rule();

// LERF-OVS, pixel-level: relevancy -> LERF post-processing -> IoU / BIoU / acc / localisation. mode "pixel".
EvalReport run_lerf_ovs(const Scene& scene, const RelevancyFn& fn, const RunOptions& opt = {});
// LERF-OVS frames and queries scored on masks from `fn` (no localisation). mode "object".
EvalReport run_lerf_ovs_masks(const Scene& scene, const MaskFn& fn, const RunOptions& opt = {});
// 3D-OVS: per-pixel argmax over the classes of segmentations/classes.txt, per-class IoU with absent = 0
// (protocol "3d-ovs"; extra.miou_ceiling the best mean any prediction can score, ovs_ceiling), or with
// opt.ovs_scoring LabelledOnly the labelled pixels and the classes in view only (protocol "3d-ovs-labelled").
EvalReport run_3dovs(const Scene& scene, const ClassRelevancyFn& fn, const RunOptions& opt = {});
// Scenes with gt/instances: every visible object's name (object_names_file, instances.h) against gt/instances
// on the test views. mode "object"; extra.object_names: the names' file relative to the scene.
EvalReport run_instances(const Scene& scene, const MaskFn& fn, const RunOptions& opt = {});

// File-name-safe version of a query: characters other than letters, digits, '-', '_', '.' become '_'.
std::string safe_file_name(const std::string& s);

}  // namespace hgs::eval
