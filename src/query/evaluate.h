// A trained hybrid model through one benchmark protocol, in object mode, pixel mode or both: the evaluation
// shared by `hgs eval`, `hgs ablate` and the Python binding (hgs.evaluate).
//
// Object mode answers each query with its best object (Session::ask) and masks that object's rendered
// opacity. On 3D-OVS (a closed list of classes per scene, background surfaces among them, the argmax over the
// classes at each pixel) every label instead classifies itself: object k takes the class c(k) whose text its
// embedding e_k is closest to (cosine), so that all the objects of a class count (also a part that SAM split off
// its whole), and the background label 0 likewise through its own embedding. The class score of a pixel is
//   score_c(p) = sum_{k : c(k) = c} A_k(p) r_k(c),
// A_k the rendered opacity of label k (A_0: the background's, through q_{n,0}) and r_k(c) the LERF relevancy of
// e_k for c; the argmax over classes is the prediction (eval/protocols.h). (Until 2026-11-27 each class chose its
// best object and background pixels took the LERF relevancy of the raw language map: 91.4 / 85.6 mIoU on two
// default-world scenes where this gives 94.7 / 86.2, 11-16 on objects-only scenes where this gives 66-69;
// docs/ablation.md.)
// Pixel mode is the protocol's relevancy of a rendered language map (query.h Relevancy: by default the
// object-conditioned map of eqs. 8-9, `lerf` the raw map as LangSplat scores its field).
#pragma once
#include <filesystem>
#include <string>
#include <vector>

#include "eval/report.h"
#include "eval/run.h"
#include "query/session.h"

namespace hgs::query {

struct EvaluateOptions {
  std::string protocol = "instances";                      // lerf-ovs | 3d-ovs | instances
  bool object = true, pixel = true;                        // modes
  query::Relevancy relevancy = query::Relevancy::Objects;  // pixel mode
  float mask_threshold = 0.5f;                             // object mode
  std::filesystem::path overlay_dir;                       // PNGs under <overlay_dir>/<mode>/ (empty: none)
  bool progress = true;
};

// The reports of the modes asked for (lerf-ovs and 3d-ovs: pixel then object; instances: object then pixel, as
// `hgs eval` has always written them); each names its mode and, in pixel mode, the relevancy variant.
std::vector<eval::EvalReport> evaluate_model(query::Session& s, const EvaluateOptions& opt);

// Whether the scene has the labels a protocol needs (gt/instances/, segmentations/, label/).
bool has_protocol_labels(const Scene& scene, const std::string& protocol);

}  // namespace hgs::query
