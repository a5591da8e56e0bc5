// Open-vocabulary queries on a trained hybrid model.
//
// Object level (the hybrid way): every object k gets one language embedding
//   e_k = normalise( sum_n q_{n,k} sigmoid(o_n) f_n )
// and the objects are ranked by the cosine of e_k with the text (their LERF relevancy against the canonical
// phrases is reported too). Relevancy is a per-pixel calibration, not a ranking of objects: it favours an
// embedding that is unlike "object" / "things" / "stuff" / "texture" over one that is like the text, and SCL's
// contrastive loss (eq. 10) leaves that offset free, so ranking by relevancy picked the wrong object for 2 of 9
// names on a trained model whose cosine ranking was right for all 9 (docs/results.md). Its mask in a view
// is its rendered opacity A_k = sum_n q_{n,k} alpha T, thresholded (default 0.5).
// Pixel level: a language map is rendered and scored per pixel (Relevancy below): by default hgs's object-embedding
// map sum_k A_k(p) e_k (each object's pooled embedding rendered with its soft object opacity, so its boundaries
// are the Gaussians'; a rule of this project, not in the paper) by its cosine with the text, or the paper's
// language map (eq. 8 summed over objects: sum_k S^pred_k = sum_n f_n alpha T) by LERF's relevancy, as LangSplat
// scores its field.
// 3D selection: the Gaussians whose hard id z_n is one of the chosen objects (or all others, for removal).
#pragma once
#include <cstdint>
#include <map>
#include <string>
#include <vector>

#include "model/gaussian_model.h"
#include "query/fragments.h"
#include "render/renderer.h"

namespace hgs::query {

struct ObjectEmbeddings {
  int num_labels = 0, dim = 0;
  std::vector<float> e;       // [L, D] unit vectors (zero for objects without Gaussians)
  std::vector<float> weight;  // [L] sum_n q_{n,k} sigmoid(o_n)
  std::vector<int> count;     // [L] Gaussians whose hard id is k
};

// Fails with a clear error when the model has no hybrid fields (hybrid/fields.h: not a hybrid model).
ObjectEmbeddings object_embeddings(const GaussianModel& m);

struct ObjectScore {
  int object = 0;
  float cosine = 0, relevancy = 0;
};
using Canonical = std::vector<std::vector<float>>;  // canonical phrase embeddings, each [D]

// Scores of every foreground object (1..K with Gaussians): cosine and LERF relevancy (relevancy.h),
// best cosine first.
std::vector<ObjectScore> score_objects(const ObjectEmbeddings& oe, const float* text, const Canonical& canon);

// The objects an answer selects from `scores` (best first, as score_objects returns them): first the anchor,
// and with min_relevancy > 0 also every other whose LERF relevancy is at least min_relevancy. Fails naming
// `text` when there is no object to choose. The anchor is the best label; given `boxes` ([L], fragments.h), the
// best label with a valid box (at least 5 opaque Gaussians hold it as their id; a rule of this project: a label
// that OF left without Gaussians renders nothing), or the best label if none has one.
// With fragment_margin > 0 and `boxes`, also every label whose cosine is below the anchor's by at most
// fragment_margin times the anchor's lead over the median label, and whose box meets the anchor's (the fragment
// rule). Given `anchorable` ([L], 1 = may anchor; session.h: QueryOptions::anchor_support), the anchor is the best
// label with a valid box that is also anchorable, falling back to the rule above when none is.
std::vector<int> choose_objects(const std::vector<ObjectScore>& scores, float min_relevancy, const std::string& text,
                                float fragment_margin = 0, const std::vector<LabelBox>* boxes = nullptr,
                                const std::vector<uint8_t>* anchorable = nullptr);

// Opacity render of objects `ks` (channel j = A_{ks[j]}). Returns [H, W, J].
std::vector<float> render_object_opacity(render::GaussianRenderer& r, const GaussianModel& m, const render::Camera& cam,
                                         const std::vector<int>& ks);
// A pixel's score for a text, from a rendered language map:
//  Objects:     hgs's object-embedding map, a rule of this project and not the paper's map: the cosine (eq. 10's
//               sim) of the text with F_obj(p) = sum_k A_k(p) e_k over every label k (the background's too),
//               A_k = sum_n q_{n,k} alpha T the object's rendered opacity and e_k its pooled embedding
//               (object_embeddings): the paper's map with each Gaussian's f_n replaced by its objects'
//               embedding. SCL (eqs. 9-10) trains f only through the objects' pooled means, so the
//               part of each f_n that differs from its object's mean stays at its random initialisation (per-pixel
//               noise in the raw map), and only through cosines among the scene's references, so an embedding's
//               offset from LERF's canonical phrases is free (the reason object ranking uses the cosine too). A
//               pixel where nothing is rendered (F = 0) scores as the view's lowest rendered pixel, not 0, which
//               would stretch LangSplat's min-max normalisation (docs/ablation.md, "Test seeds at medium noise").
//               The default (docs/ablation.md, "Pixel mode against object mode").
//  ObjectsLerf: LERF's relevancy (the min over the canonical phrases of the pairwise softmax at temperature 10) of
//               hgs's object-embedding map (not in the paper).
//  Lerf:        the paper's language map F(p) = sum_n f_n alpha T (eq. 8 summed over the objects k, since
//               sum_k q_{n,k} = 1) scored with LERF's relevancy, nothing else: LangSplat's evaluation of its own
//               field. query/evaluate.h reports it beside the default in every pixel evaluation.
//  Foreground:  the paper's map's relevancy times the rendered foreground opacity sum_n (1 - q_{n,0}) alpha T, and
//               0 where nothing is rendered (alpha < 1e-4) (not in the paper).
// On 3D-OVS (the argmax over classes at each pixel) Objects and ObjectsLerf agree: for one pixel LERF's relevancy
// grows with the cosine.
enum class Relevancy { Objects, ObjectsLerf, Lerf, Foreground };
const char* relevancy_name(Relevancy v);  // "objects" | "objects-lerf" | "lerf" | "foreground"
// What a variant scores, in words, for reports and help: e.g. "LERF's relevancy of the paper's language map ...".
const char* relevancy_description(Relevancy v);
Relevancy parse_relevancy(const std::string& name);  // fails naming the accepted values

// Per-pixel relevancy of a rendered language map for a query: [H, W]. `oe`: the model's object embeddings for
// Relevancy::Objects and ObjectsLerf (computed here when null).
std::vector<float> render_relevancy(render::GaussianRenderer& r, const GaussianModel& m, const render::Camera& cam,
                                    const float* text, const Canonical& canon, Relevancy variant = Relevancy::Objects,
                                    const ObjectEmbeddings* oe = nullptr);
// The same for several queries from one render: texts[t] is [D]; result [T][H, W], each equal to
// render_relevancy(texts[t]).
std::vector<std::vector<float>> render_relevancies(render::GaussianRenderer& r, const GaussianModel& m,
                                                   const render::Camera& cam, const std::vector<const float*>& texts,
                                                   const Canonical& canon, Relevancy variant = Relevancy::Objects,
                                                   const ObjectEmbeddings* oe = nullptr);

// Closed-set classification by objects (3D-OVS object mode, query/evaluate.h): every class c takes its best
// foreground object k(c) (the highest cosine: score_objects' first, even where Session::ask's anchor is a later
// label because that one holds no Gaussians), and every label no class took (the background 0, a part SAM split
// off its whole, a second instance, a track's later id) takes the class c(k) its embedding is closest to; the score of
// class c at a pixel is the sum over its labels of A_k(p) r_k(c), A_k the label's rendered opacity and r_k(c) the LERF
// relevancy of e_k for text c. texts[c] is [D]; result [C][H, W].
std::vector<std::vector<float>> object_class_scores(render::GaussianRenderer& r, const GaussianModel& m,
                                                    const render::Camera& cam, const ObjectEmbeddings& oe,
                                                    const std::vector<const float*>& texts, const Canonical& canon);

// Copy of the model keeping Gaussians whose hard id is in `objects` (or not in it when `remove`).
GaussianModel select_objects(const GaussianModel& m, const std::vector<int>& objects, bool remove);

}  // namespace hgs::query
