#include "query/evaluate.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/excerpt.h"

namespace hgs::query {
namespace fs = std::filesystem;

namespace {

// Every protocol: name, labels, 3D-OVS scoring, LERF windows scaled.
const std::vector<ProtocolSpec>& protocol_table() {
  using eval::OvsScoring;
  static const std::vector<ProtocolSpec> t = {
      {"instances", "instances", OvsScoring::Protocol, false},
      {"instances-scaled", "instances", OvsScoring::Protocol, true},
      {"3d-ovs", "3d-ovs", OvsScoring::Protocol, false},
      {"3d-ovs-labelled", "3d-ovs", OvsScoring::LabelledOnly, false},
      {"lerf-ovs", "lerf-ovs", OvsScoring::Protocol, false},
      {"lerf-ovs-scaled", "lerf-ovs", OvsScoring::Protocol, true},
  };
  return t;
}

// The folder holding a protocol's ground truth.
fs::path protocol_label_dir(const Scene& scene, const std::string& protocol) {
  const std::string labels = parse_protocol(protocol).labels;
  if (labels == "instances") return scene.root / "gt" / "instances";
  if (labels == "3d-ovs") return scene.segmentation_dir();
  return scene.label_dir();
}

// 3D-OVS object mode (evaluate.h): every label classifies itself (query.h object_class_scores).
std::vector<std::vector<float>> object_class_scores(query::Session& s, render::GaussianRenderer& r, int view,
                                                    const std::vector<std::string>& classes) {
  std::vector<const float*> texts;  // [C] each [D]
  for (const auto& c : classes) texts.push_back(s.text().embed(c).data());
  return query::object_class_scores(r, s.model(), s.camera(view), s.objects(), texts, s.text().canonical());
}

}  // namespace

const std::vector<std::string>& protocol_names() {
  static const std::vector<std::string> names = [] {
    std::vector<std::string> n;
    for (const auto& p : protocol_table()) n.push_back(p.name);
    return n;
  }();
  return names;
}

ProtocolSpec parse_protocol(const std::string& name) {
  for (const auto& p : protocol_table())
    if (p.name == name) return p;
  std::string list;
  for (const auto& n : protocol_names()) list += (list.empty() ? "" : ", ") + n;
  fail("unknown protocol '{}' (one of {})", excerpt(name), list);
}

bool has_protocol_labels(const Scene& scene, const std::string& protocol) {
  return fs::is_directory(protocol_label_dir(scene, protocol));
}

std::vector<eval::EvalReport> evaluate_model(query::Session& s, const EvaluateOptions& o) {
  if (!has_protocol_labels(s.scene(), o.protocol))
    fail("{}: no labels for the {} protocol (needs {})", s.scene().root.string(), o.protocol,
         protocol_label_dir(s.scene(), o.protocol).string());
  const ProtocolSpec spec = parse_protocol(o.protocol);
  eval::RunOptions opt;
  opt.progress = o.progress;
  opt.ovs_scoring = spec.ovs_scoring;
  opt.lerf_scaled = spec.lerf_scaled;
  opt.query_set = o.query_set;
  if (!o.query_set.empty() && spec.labels != "instances")
    fail("--queries: query sets are asked with the instances protocols (not {})", spec.name);
  query::Relevancy rel = o.relevancy;  // the pixel report being run
  auto png_dir = [&](const char* mode) { return o.overlay_dir.empty() ? fs::path() : o.overlay_dir / mode; };
  auto object_fn = [&](int view, const std::string& q, std::vector<float>* heat) {
    return s.answer_mask(view, q, o.object_query, heat);
  };
  auto pixel_fn = [&](int view, const std::string& q) { return s.pixel_relevancy(view, q, rel); };
  auto pixel_mask_fn = [&](int view, const std::string& q, std::vector<float>* heat) {
    std::vector<float> r = s.pixel_relevancy(view, q, rel);
    const View& v = s.scene().views[view];
    eval::Mask m = eval::lerf_postprocess(r, v.width, v.height, eval::lerf_options_for(opt, v.width)).mask;
    if (heat) *heat = std::move(r);
    return m;
  };
  render::GaussianRenderer renderer;
  std::vector<eval::EvalReport> reports;
  auto run_pixel_as = [&](const char* mode) {
    opt.overlay_dir = png_dir(mode);
    if (spec.labels == "lerf-ovs") {
      reports.push_back(eval::run_lerf_ovs(s.scene(), pixel_fn, opt));
    } else if (spec.labels == "3d-ovs") {
      reports.push_back(eval::run_3dovs(
          s.scene(),
          [&](int view, const std::vector<std::string>& classes) { return s.pixel_relevancies(view, classes, rel); },
          opt));
    } else {
      reports.push_back(eval::run_instances(s.scene(), pixel_mask_fn, opt));
    }
    reports.back().mode = mode;
    reports.back().protocol = spec.name;
    reports.back().extra["relevancy"] = query::relevancy_name(rel);
    reports.back().extra["pixel_score"] = query::relevancy_description(rel);
    if (spec.lerf_scaled) reports.back().extra["lerf_windows"] = eval::scaled_lerf_rule();
  };
  auto run_pixel = [&] {
    rel = o.relevancy;
    run_pixel_as("pixel");
    if (o.paper_map && o.relevancy != query::Relevancy::Lerf) {
      rel = query::Relevancy::Lerf;
      run_pixel_as("pixel-paper-map");
    }
  };
  auto run_object = [&] {
    opt.overlay_dir = png_dir("object");
    if (spec.labels == "lerf-ovs") {
      reports.push_back(eval::run_lerf_ovs_masks(s.scene(), object_fn, opt));
    } else if (spec.labels == "3d-ovs") {
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
    reports.back().protocol = spec.name;
    // The anchor's rule when it is not the default's (3D-OVS classifies every label and uses no anchor).
    if (o.object_query.anchor_support > 0 && spec.labels != "3d-ovs")
      reports.back().extra["anchor_support"] = std::round(double(o.object_query.anchor_support) * 1e6) / 1e6;
  };
  if (spec.labels == "instances") {
    if (o.object) run_object();
    if (o.pixel) run_pixel();
  } else {
    if (o.pixel) run_pixel();
    if (o.object) run_object();
  }
  return reports;
}

}  // namespace hgs::query
