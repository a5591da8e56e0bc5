#include "query/evaluate.h"

#include <algorithm>

#include "core/error.h"
#include "render/camera_from_view.h"

namespace hgs::query {
namespace fs = std::filesystem;

namespace {

// The folder holding a protocol's ground truth.
fs::path protocol_label_dir(const Scene& scene, const std::string& protocol) {
  if (protocol == "instances") return scene.root / "gt" / "instances";
  if (protocol == "3d-ovs" || protocol == "3d-ovs-labelled") return scene.segmentation_dir();
  if (protocol == "lerf-ovs") return scene.label_dir();
  fail("unknown protocol '{}' (lerf-ovs, 3d-ovs, 3d-ovs-labelled or instances)", protocol);
}

// 3D-OVS object mode (evaluate.h): every label classifies itself (query.h object_class_scores).
std::vector<std::vector<float>> object_class_scores(query::Session& s, render::GaussianRenderer& r, int view,
                                                    const std::vector<std::string>& classes) {
  std::vector<const float*> texts;  // [C] each [D]
  for (const auto& c : classes) texts.push_back(s.text().embed(c).data());
  return query::object_class_scores(r, s.model(), render::camera_from_view(s.scene().views.at(view)), s.objects(),
                                    texts, s.text().canonical());
}

}  // namespace

bool has_protocol_labels(const Scene& scene, const std::string& protocol) {
  return fs::is_directory(protocol_label_dir(scene, protocol));
}

std::vector<eval::EvalReport> evaluate_model(query::Session& s, const EvaluateOptions& o) {
  if (!has_protocol_labels(s.scene(), o.protocol))
    fail("{}: no labels for the {} protocol (needs {})", s.scene().root.string(), o.protocol,
         protocol_label_dir(s.scene(), o.protocol).string());
  eval::RunOptions opt;
  opt.progress = o.progress;
  const bool ovs = o.protocol == "3d-ovs" || o.protocol == "3d-ovs-labelled";
  if (o.protocol == "3d-ovs-labelled") opt.ovs_scoring = eval::OvsScoring::LabelledOnly;
  const query::Relevancy rel = o.relevancy;
  auto png_dir = [&](const char* mode) { return o.overlay_dir.empty() ? fs::path() : o.overlay_dir / mode; };
  auto object_fn = [&](int view, const std::string& q, std::vector<float>* heat) {
    return s.answer_mask(view, q, o.mask_threshold, heat);
  };
  auto pixel_fn = [&](int view, const std::string& q) { return s.pixel_relevancy(view, q, rel); };
  auto pixel_mask_fn = [&](int view, const std::string& q, std::vector<float>* heat) {
    std::vector<float> r = s.pixel_relevancy(view, q, rel);
    const View& v = s.scene().views[view];
    eval::Mask m = eval::lerf_postprocess(r, v.width, v.height, opt.lerf).mask;
    if (heat) *heat = std::move(r);
    return m;
  };
  render::GaussianRenderer renderer;
  std::vector<eval::EvalReport> reports;
  auto run_pixel = [&] {
    opt.overlay_dir = png_dir("pixel");
    if (o.protocol == "lerf-ovs") {
      reports.push_back(eval::run_lerf_ovs(s.scene(), pixel_fn, opt));
    } else if (ovs) {
      reports.push_back(eval::run_3dovs(
          s.scene(),
          [&](int view, const std::vector<std::string>& classes) { return s.pixel_relevancies(view, classes, rel); },
          opt));
    } else {
      reports.push_back(eval::run_instances(s.scene(), pixel_mask_fn, opt));
    }
    reports.back().mode = "pixel";
    reports.back().extra["relevancy"] = query::relevancy_name(rel);
  };
  auto run_object = [&] {
    opt.overlay_dir = png_dir("object");
    if (o.protocol == "lerf-ovs") {
      reports.push_back(eval::run_lerf_ovs_masks(s.scene(), object_fn, opt));
    } else if (ovs) {
      reports.push_back(eval::run_3dovs(
          s.scene(),
          [&](int view, const std::vector<std::string>& classes) {
            return object_class_scores(s, renderer, view, classes);
          },
          opt));
    } else {
      reports.push_back(eval::run_instances(s.scene(), object_fn, opt));
    }
    reports.back().mode = "object";
  };
  if (o.protocol == "instances") {
    if (o.object) run_object();
    if (o.pixel) run_pixel();
  } else {
    if (o.pixel) run_pixel();
    if (o.object) run_object();
  }
  return reports;
}

}  // namespace hgs::query
