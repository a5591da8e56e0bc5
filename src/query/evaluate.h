// A trained hybrid model through one benchmark protocol, in object mode, pixel mode or both: the evaluation
// shared by `hgs eval`, `hgs ablate` and the Python binding (hgs.evaluate).
//
// Object mode answers each query with its best object (Session::ask) and masks that object's rendered
// opacity. On 3D-OVS (a closed list of classes per scene, background surfaces among them, the argmax over the
// classes at each pixel) the objects are classified: every class takes its best object k(c), and every label no
// class took takes the class c(k) its embedding is closest to (cosine): the background label 0 through its own
// embedding, a part that SAM split off its whole (the whole answers the class, the part joins it), a second
// instance. The class score of a pixel is
//   score_c(p) = sum over the labels k of class c of A_k(p) r_k(c)
// (query::object_class_scores), A_k the rendered opacity of label k and r_k(c) the LERF relevancy of e_k for c;
// the argmax over classes is the prediction (eval/protocols.h). docs/ablation.md compares this with scoring the
// background pixels by the raw language map's relevancy (A_0(p) r_c(p)) and unchosen objects as nothing.
// "3d-ovs-labelled" is 3D-OVS scored on the pixels the ground truth labels and the classes each frame shows
// (eval::OvsScoring::LabelledOnly): what 3D-OVS measures on its own scenes, whose classes cover every pixel and
// are all in view, on generated scenes that show the sky or leave classes out of some views.
// Pixel mode is the protocol's relevancy of a rendered language map (query.h Relevancy). By default it scores
// hgs's object-embedding map sum_k A_k(p) e_k (each object's pooled embedding rendered with its opacity; a rule of
// this project, not in the paper); `lerf` scores the paper's language map (eq. 8 summed over objects =
// sum_n f_n alpha T) with LERF's relevancy, as LangSplat scores its field. With the default rule the paper's map
// is evaluated too and reported beside it (mode "pixel-paper-map", EvaluateOptions::paper_map).
#pragma once
#include <filesystem>
#include <string>
#include <vector>

#include "eval/report.h"
#include "eval/run.h"
#include "query/session.h"

namespace hgs::query {

// The protocols by name: a benchmark's labels and how they are scored.
//   lerf-ovs, 3d-ovs, instances: as the benchmarks' papers score them;
//   3d-ovs-labelled: 3D-OVS on the labelled pixels and the classes in view (eval::OvsScoring::LabelledOnly);
//   lerf-ovs-scaled, instances-scaled: pixel mode's LERF post-processing windows (LangSplat's 30-px box and 7x7
//   majority filter, set on frames about 1000 px wide) scaled to each image (eval::scaled_lerf_options), for
//   images far smaller than LERF's; object mode is the same as without "-scaled".
struct ProtocolSpec {
  std::string name;    // as given
  std::string labels;  // the benchmark whose labels it reads: lerf-ovs, 3d-ovs or instances
  eval::OvsScoring ovs_scoring = eval::OvsScoring::Protocol;
  bool lerf_scaled = false;
};
// Fails with the list of names on an unknown one.
ProtocolSpec parse_protocol(const std::string& name);
const std::vector<std::string>& protocol_names();

struct EvaluateOptions {
  std::string protocol = "instances";                      // a protocol_names() entry
  bool object = true, pixel = true;                        // modes
  query::Relevancy relevancy = query::Relevancy::Objects;  // pixel mode
  // Pixel mode with a relevancy other than Lerf: also the paper's map (Relevancy::Lerf) as a second pixel report,
  // mode "pixel-paper-map", right after the first (overlays under <overlay_dir>/pixel-paper-map/).
  bool paper_map = true;
  // Object mode: how an answer's labels are chosen and masked (mask threshold, fragment rule, anchor support).
  QueryOptions object_query;
  std::filesystem::path overlay_dir;  // PNGs under <overlay_dir>/<mode>/ (empty: none)
  bool progress = true;
  std::string query_set;  // instances: a query set of gt/queries.json (eval::RunOptions::query_set); empty = names
};

// The reports of the modes asked for (lerf-ovs and 3d-ovs: pixel then object; instances: object then pixel, as
// `hgs eval` has always written them; "pixel-paper-map" right after "pixel" when asked for); each names its mode
// and, in pixel mode, the relevancy variant (extra "relevancy"; "lerf" for the paper's map).
std::vector<eval::EvalReport> evaluate_model(query::Session& s, const EvaluateOptions& opt);

// Whether the scene has the labels a protocol needs (gt/instances/, segmentations/, label/).
bool has_protocol_labels(const Scene& scene, const std::string& protocol);

}  // namespace hgs::query
