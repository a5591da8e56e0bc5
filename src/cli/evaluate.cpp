#include "cli/evaluate.h"

#include <algorithm>

#include "core/error.h"
#include "render/camera_from_view.h"

namespace hgs::cli {
namespace fs = std::filesystem;

bool has_protocol_labels(const Scene& scene, const std::string& protocol) {
  if (protocol == "instances") return fs::is_directory(scene.root / "gt" / "instances");
  if (protocol == "3d-ovs") return fs::is_directory(scene.segmentation_dir());
  if (protocol == "lerf-ovs") return fs::is_directory(scene.label_dir());
  fail("unknown protocol '{}' (lerf-ovs, 3d-ovs or instances)", protocol);
}

namespace {

// 3D-OVS object mode (evaluate.h): score_c(p) = A_{k(c)}(p) r_obj(c) + A_0(p) r_c(p) for every class c.
std::vector<std::vector<float>> object_class_scores(query::Session& s, render::GaussianRenderer& r, int view,
                                                    const std::vector<std::string>& classes) {
  std::vector<int> ids = {0}, chosen;
  std::vector<float> rel_obj;
  for (const auto& c : classes) {
    const query::ObjectAnswer ans = s.ask(c);
    chosen.push_back(ans.chosen[0]);
    for (const auto& sc : ans.scores)
      if (sc.object == chosen.back()) rel_obj.push_back(sc.relevancy);
    if (std::find(ids.begin(), ids.end(), chosen.back()) == ids.end()) ids.push_back(chosen.back());
  }
  const View& v = s.scene().views.at(view);
  const std::vector<float> A = query::render_object_opacity(r, s.model(), render::camera_from_view(v), ids);  // [HW, J]
  const size_t HW = size_t(v.width) * v.height, J = ids.size();
  std::vector<std::vector<float>> maps;
  for (size_t c = 0; c < classes.size(); ++c) {
    const size_t j = std::find(ids.begin(), ids.end(), chosen[c]) - ids.begin();
    std::vector<float> rc = s.pixel_relevancy(view, classes[c], query::Relevancy::Lerf);  // [H, W]
    for (size_t p = 0; p < HW; ++p) rc[p] = A[p * J + j] * rel_obj[c] + A[p * J] * rc[p];
    maps.push_back(std::move(rc));
  }
  return maps;
}

}  // namespace

std::vector<eval::EvalReport> evaluate_model(query::Session& s, const EvaluateOptions& o) {
  if (!has_protocol_labels(s.scene(), o.protocol))
    fail("{}: no labels for the {} protocol (needs {})", s.scene().root.string(), o.protocol,
         o.protocol == "instances" ? "gt/instances/" : o.protocol == "3d-ovs" ? "segmentations/" : "label/");
  eval::RunOptions opt;
  opt.progress = o.progress;
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
    } else if (o.protocol == "3d-ovs") {
      reports.push_back(eval::run_3dovs(s.scene(), [&](int view, const std::vector<std::string>& classes) {
        std::vector<std::vector<float>> maps;
        for (auto& c : classes) maps.push_back(s.pixel_relevancy(view, c, rel));
        return maps;
      }, opt));
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
    } else if (o.protocol == "3d-ovs") {
      reports.push_back(eval::run_3dovs(s.scene(), [&](int view, const std::vector<std::string>& classes) {
        return object_class_scores(s, renderer, view, classes);
      }, opt));
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

}  // namespace hgs::cli
