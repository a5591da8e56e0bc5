// hgs.QuerySession: query::Session on a scene and a model shared with Python (not copied): text -> ranked objects
// (cosine and LERF relevancy), per-view object opacity and masks, pixel relevancy maps, the protocols of
// query/evaluate.h as report dicts. hgs.query / hgs.evaluate (python/hgs/__init__.py) build one per call.
// Thread safety: a session renders through its one renderer and caches text embeddings, so every call takes the
// session's lock (waiting with the GIL released): calls from several Python threads (QueryResult.mask through a
// ThreadPoolExecutor) run one after the other, each on all the OpenMP threads. Without it they corrupted the heap.
#include <mutex>

#include <nlohmann/json.hpp>

#include "common.h"
#include "core/error.h"
#include "core/excerpt.h"
#include "eval/report.h"
#include "query/evaluate.h"
#include "query/session.h"

namespace hgs::py {
namespace {

// The session and the lock every call on it takes.
struct LockedSession {
  std::shared_ptr<query::Session> s;
  std::mutex m;
};
using SessionPtr = std::shared_ptr<LockedSession>;

// Runs fn(session) holding its lock, the GIL released (a call waiting for the lock must not hold the GIL: the
// holder never needs it, but other Python threads do).
template <class F>
auto locked(LockedSession& ls, F&& fn) {
  pb::gil_scoped_release nogil;
  std::lock_guard<std::mutex> l(ls.m);
  return fn(*ls.s);
}

query::Relevancy relevancy_variant(const std::string& r) { return query::parse_relevancy(r); }

// The anchor's support is a fraction (query::QueryOptions::anchor_support); `where` names the call in the error.
float checked_support(float r, const char* where) {
  if (!(r >= 0.f && r <= 1.f)) fail("{}: anchor_support must be in [0, 1], got {}", where, r);
  return r;
}

pb::list ask(LockedSession& ls, const std::string& text, float min_relevancy, float fragment_margin,
             float anchor_support) {
  const float support = checked_support(anchor_support, "QuerySession.ask");
  const query::ObjectAnswer a = locked(ls, [&](query::Session& s) {
    return s.ask(text, {min_relevancy, 0.5f, fragment_margin, support});
  });
  const query::Session& s = *ls.s;  // object_name reads the scene's names only
  pb::list out;
  for (const auto& sc : a.scores) {
    pb::dict d;
    d["id"] = sc.object;
    d["name"] = s.object_name(sc.object);
    d["relevancy"] = sc.relevancy;
    d["cosine"] = sc.cosine;
    d["chosen"] = std::find(a.chosen.begin(), a.chosen.end(), sc.object) != a.chosen.end();
    d["anchor"] = sc.object == a.chosen.front();  // choose_objects: the first chosen
    out.append(d);
  }
  return out;
}

pb::array object_opacity(LockedSession& ls, pb::handle view, const std::vector<int>& objects) {
  const int vi = view_index(ls.s->scene(), view);  // the scene is read-only
  const View& v = ls.s->scene().views[vi];
  std::vector<float> a = locked(ls, [&](query::Session& s) { return s.object_opacity(vi, objects); });
  return take_vector(std::move(a), {v.height, v.width});
}

pb::array pixel_relevancy(LockedSession& ls, pb::handle view, const std::string& text, const std::string& variant) {
  const int vi = view_index(ls.s->scene(), view);
  const View& v = ls.s->scene().views[vi];
  const query::Relevancy r = relevancy_variant(variant);
  std::vector<float> a = locked(ls, [&](query::Session& s) { return s.pixel_relevancy(vi, text, r); });
  return take_vector(std::move(a), {v.height, v.width});
}

std::string evaluate(LockedSession& ls, const std::string& protocol, const std::string& mode,
                     const std::string& relevancy, float mask_threshold, const std::string& overlay_dir, bool progress,
                     bool paper_map, const std::string& queries, float fragment_margin, float anchor_support) {
  const query::Session& s = *ls.s;
  query::parse_protocol(protocol);  // fails with the list of protocols
  if (mode != "object" && mode != "pixel" && mode != "both")
    fail("mode must be object, pixel or both, got '{}'", excerpt(mode));
  if (!query::has_protocol_labels(s.scene(), protocol))
    fail("{}: no labels for the {} protocol", s.scene().root.string(), protocol);
  query::EvaluateOptions o;
  o.protocol = protocol;
  o.object = mode != "pixel";
  o.pixel = mode != "object";
  o.relevancy = relevancy_variant(relevancy);
  o.paper_map = paper_map;
  o.object_query.mask_threshold = mask_threshold;
  o.overlay_dir = overlay_dir;
  o.progress = progress;
  o.query_set = queries;
  o.object_query.fragment_margin = fragment_margin;
  o.object_query.anchor_support = checked_support(anchor_support, "QuerySession.evaluate");
  nlohmann::json reports = nlohmann::json::array();
  locked(ls, [&](query::Session& session) {
    for (const auto& r : query::evaluate_model(session, o)) reports.push_back(eval::report_json(r));
    return 0;
  });
  return nlohmann::json{{"reports", reports}}.dump();
}

}  // namespace

void bind_query(pb::module_& m) {
  pb::class_<LockedSession, SessionPtr>(
      m, "QuerySession",
      "A scene and a trained hybrid model ready for text queries (the model must not change while it is used). "
      "Safe to share between threads: calls on one session run one at a time")
      .def(pb::init([](pb::object scene_obj, pb::object model_obj, const std::string& clip, pb::object near_plane) {
             auto scene = object_arg<Scene>(scene_obj, "QuerySession", "scene", "an hgs.Scene");
             auto model = object_arg<GaussianModel>(model_obj, "QuerySession", "model", "an hgs.Model");
             const float near = model_near_plane_of(model_obj, near_plane, "QuerySession");
             pb::gil_scoped_release nogil;
             auto ls = std::make_shared<LockedSession>();
             ls->s = std::make_shared<query::Session>(scene, model, clip, "hgs.query", near);
             return ls;
           }),
           pb::arg("scene"), pb::arg("model"), pb::arg("clip") = "", pb::arg("near_plane") = pb::none(),
           "Object embeddings of the model; texts are embedded from the scene's text_embeddings.json, or by the "
           "OpenCLIP weights `clip` (.safetensors) when given. Renders cull at near_plane (default: the model's "
           "near_plane attribute, set by Model.load and hgs.train, else 0.01)")
      .def("ask", &ask, pb::arg("text"), pb::arg("min_relevancy") = 0.f,
           pb::arg("fragment_margin") = query::kFragmentMargin, pb::arg("anchor_support") = 0.f,
           "Every object ranked for `text`, best first: dicts with id, name, relevancy, cosine, chosen (the best "
           "one, plus every other with relevancy >= min_relevancy when it is > 0, plus the fragment rule's labels: "
           "within fragment_margin of the best cosine and where its Gaussians lie; a rule of hgs, "
           "query/fragments.h; 0 = off) and anchor (the first chosen). anchor_support > 0: the anchor must render at "
           "least that fraction of the pixels its mask id covers in the training views' masks (a rule of hgs, off "
           "by default; query/session.h)")
      .def("object_opacity", &object_opacity, pb::arg("view"), pb::arg("objects"),
           "Rendered opacity of the objects in a view, summed: float32 [H, W]")
      .def("pixel_relevancy", &pixel_relevancy, pb::arg("view"), pb::arg("text"), pb::arg("relevancy") = "objects",
           "A pixel score map for the text: float32 [H, W] (relevancy: objects = the cosine with hgs's "
           "object-embedding map sum_k A_k e_k, each object's pooled embedding rendered with its opacity, not in the "
           "paper; objects-lerf = LERF's relevancy of that map; lerf = the paper's language map, eq. 8 summed over "
           "objects = sum_n f_n alpha T, scored with LERF's relevancy as LangSplat scores its field; foreground = "
           "lerf times the foreground opacity; query/query.h)")
      .def(
          "object_name", [](const LockedSession& ls, int id) { return ls.s->object_name(id); }, pb::arg("id"))
      .def("evaluate", &evaluate, pb::arg("protocol"), pb::arg("mode") = "both", pb::arg("relevancy") = "objects",
           pb::arg("mask_threshold") = 0.5f, pb::arg("overlay_dir") = "", pb::arg("progress") = false,
           pb::arg("paper_map") = true, pb::arg("queries") = "", pb::arg("fragment_margin") = query::kFragmentMargin,
           pb::arg("anchor_support") = 0.f,
           "Runs a benchmark protocol (lerf-ovs, 3d-ovs, instances) and returns {\"reports\": [...]} as JSON text; "
           "pixel mode with a relevancy other than lerf adds the paper's language map as mode pixel-paper-map "
           "(paper_map=False: not); queries: a query set of gt/queries.json for the instances protocols (synonyms, "
           "hypernyms, attributes; empty = the names); fragment_margin: object mode's fragment rule (0 = off); "
           "anchor_support: object mode's anchor support (as ask; 0 = off)");
}

}  // namespace hgs::py
