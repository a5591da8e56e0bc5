// A loaded scene + trained hybrid model ready for queries: the piece shared by `hgs query`, `hgs eval` and
// the viewer. Object-level answers pick the objects whose embedding is most relevant to the text; masks are
// their rendered opacity above a threshold. Pixel-level answers render the language map's relevancy.
#pragma once
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "eval/metrics.h"
#include "model/gaussian_model.h"
#include "query/fragments.h"
#include "query/query.h"
#include "query/text.h"
#include "render/renderer.h"
#include "scene/scene.h"

namespace hgs::query {

struct QueryOptions {
  float min_relevancy = 0.f;    // > 0: every object at or above it is chosen (at least the anchor, choose_objects)
  float mask_threshold = 0.5f;  // object mode: mask = sum of chosen objects' opacity > threshold
  // The fragment rule (fragments.h, a rule of this project): labels within this cosine of the anchor (query.h:
  // choose_objects) whose Gaussians lie where its Gaussians lie join the answer; 0 = the anchor alone.
  float fragment_margin = kFragmentMargin;
  // > 0: the anchor (query.h: choose_objects) must render, over the training views, at least this fraction of the
  // pixels its mask id covers in those views' masks (rendered opacity > mask_threshold). A rule of this project,
  // off by default: a label that OF left on a few Gaussians hidden under a surface, or on almost none of the
  // object it labelled, can outrank the object's visible label and answer with nothing (docs/ablation.md, "OF
  // alone on tabletop 7003"). Needs the scene's masks/; counted once per session and mask_threshold.
  float anchor_support = 0.f;
};

struct ObjectAnswer {
  std::string text;
  std::vector<ObjectScore> scores;  // every object, best first
  std::vector<int> chosen;          // object ids
};

class Session {
 public:
  // Renders cull at the near plane in the config.json beside `model_ply` (model/near_plane.h).
  Session(const std::filesystem::path& scene, const std::filesystem::path& model_ply, int downscale,
          const std::filesystem::path& clip_path);
  // On a scene and a model already in memory, shared, not copied (the Python binding); `where` names the model
  // in errors. The model must not change while the session lives (its object embeddings are computed here).
  Session(std::shared_ptr<const Scene> scene, std::shared_ptr<const GaussianModel> model,
          const std::filesystem::path& clip_path, const std::string& where,
          float near_plane = render::kDefaultNearPlane);

  const Scene& scene() const { return *scene_; }
  const GaussianModel& model() const { return *model_; }
  TextEmbedder& text() { return text_; }
  const ObjectEmbeddings& objects() const { return oe_; }
  std::string object_name(int id) const;  // masks/objects.json name, or "object <id>"
  // The renderer's camera of a scene view, culling at the model's near plane.
  render::Camera camera(int view) const;

  ObjectAnswer ask(const std::string& text, const QueryOptions& opt = {});
  // Opacity of the chosen objects in a view, summed: [H, W] (heatmap of the object mode).
  std::vector<float> object_opacity(int view, const std::vector<int>& objects);
  // Mask of the chosen objects: their summed opacity > threshold; `opacity` (optional) receives that sum.
  eval::Mask object_mask(int view, const std::vector<int>& objects, float threshold,
                         std::vector<float>* opacity = nullptr);
  // Object-level answer in one view: the labels chosen for `text` (ask with `opt`), their mask (opacity >
  // opt.mask_threshold) and (optionally) their opacity.
  eval::Mask answer_mask(int view, const std::string& text, const QueryOptions& opt,
                         std::vector<float>* opacity = nullptr);
  // Per label [L]: pixels its id covers in the training views' masks, and pixels where its rendered opacity is
  // above `threshold` in those views (QueryOptions::anchor_support; counted on first use, then kept).
  const std::vector<double>& mask_area();
  const std::vector<double>& rendered_area(float threshold);
  // Relevancy of a rendered language map (query.h, Relevancy): [H, W].
  std::vector<float> pixel_relevancy(int view, const std::string& text, Relevancy variant = Relevancy::Objects);
  // The same for several texts from one render of the view's language map: [T][H, W].
  std::vector<std::vector<float>> pixel_relevancies(int view, const std::vector<std::string>& texts,
                                                    Relevancy variant = Relevancy::Objects);

 private:
  std::shared_ptr<const Scene> scene_;
  std::shared_ptr<const GaussianModel> model_;
  TextEmbedder text_;
  ObjectEmbeddings oe_;
  std::vector<LabelBox> boxes_;                    // [L] for the fragment rule (fragments.h)
  std::vector<double> mask_area_, rendered_area_;  // [L] each, empty until counted
  float rendered_threshold_ = -1.f;                // the threshold rendered_area_ was counted at
  render::GaussianRenderer renderer_;
  float near_plane_ = render::kDefaultNearPlane;

  void check_dims(const std::string& where) const;  // the model's D against the text embeddings'
};

}  // namespace hgs::query
