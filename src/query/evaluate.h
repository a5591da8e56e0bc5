// A trained hybrid model through one benchmark protocol, in object mode, pixel mode or both: the evaluation
// shared by `hgs eval`, `hgs ablate` and the Python binding (hgs.evaluate).
//
// Object mode answers each query with its best object (Session::ask) and masks that object's rendered
// opacity. On 3D-OVS, whose classes include background surfaces (walls, floors, tables) that no object mask
// names, the class score of a pixel is
//   score_c(p) = A_{k(c)}(p) r_obj(c)  +  A_0(p) r_c(p),
// A_k the rendered opacity of object k (A_0: the background's, through q_{n,0}), k(c) the object chosen for c,
// r_obj(c) its object relevancy and r_c(p) the LERF relevancy of the rendered language map: object pixels take
// the class of their object's answer, background pixels the class the language field gives them (both terms
// are LERF relevancies, on one scale). The argmax over classes is the prediction (eval/protocols.h).
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
