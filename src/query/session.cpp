#include "query/session.h"

#include <algorithm>

#include "core/error.h"
#include "model/near_plane.h"
#include "model/ply.h"
#include "render/camera_from_view.h"

namespace hgs::query {

Session::Session(const std::filesystem::path& scene, const std::filesystem::path& model_ply, int downscale,
                 const std::filesystem::path& clip_path)
    : scene_(std::make_shared<const Scene>(load_scene(scene, {downscale, false}))),
      model_(std::make_shared<const GaussianModel>(read_model_ply(model_ply))),
      text_(*scene_, clip_path),
      oe_(object_embeddings(*model_)),
      boxes_(label_boxes(*model_, oe_.num_labels)),
      near_plane_(model_near_plane(model_ply)) {
  check_dims(model_ply.string());
}

Session::Session(std::shared_ptr<const Scene> scene, std::shared_ptr<const GaussianModel> model,
                 const std::filesystem::path& clip_path, const std::string& where, float near_plane)
    : scene_(std::move(scene)),
      model_(std::move(model)),
      text_(*scene_, clip_path),
      oe_(object_embeddings(*model_)),
      boxes_(label_boxes(*model_, oe_.num_labels)),
      near_plane_(checked_near_plane(near_plane, where + ": near_plane")) {
  check_dims(where);
}

render::Camera Session::camera(int view) const { return render::camera_from_view(scene_->views.at(view), near_plane_); }

void Session::check_dims(const std::string& where) const {
  if (oe_.dim != text_.dim())
    fail("{}: the model's language embeddings have D = {} but the text embeddings have D = {}", where, oe_.dim,
         text_.dim());
}

std::string Session::object_name(int id) const {
  auto it = scene_->object_names.find(id);
  return it != scene_->object_names.end() ? it->second : fmt::format("object {}", id);
}

ObjectAnswer Session::ask(const std::string& text, const QueryOptions& opt) {
  ObjectAnswer a;
  a.text = text;
  const auto& e = text_.embed(text);
  a.scores = score_objects(oe_, e.data(), text_.canonical());
  std::vector<uint8_t> anchorable;
  if (opt.anchor_support > 0) {
    const std::vector<double>&masks = mask_area(), &rendered = rendered_area(opt.mask_threshold);
    anchorable.resize(oe_.num_labels);
    for (int k = 0; k < oe_.num_labels; ++k) anchorable[k] = rendered[k] >= opt.anchor_support * masks[k];
  }
  a.chosen = choose_objects(a.scores, opt.min_relevancy, text, opt.fragment_margin, &boxes_,
                            anchorable.empty() ? nullptr : &anchorable);
  return a;
}

const std::vector<double>& Session::mask_area() {
  if (!mask_area_.empty()) return mask_area_;
  if (!scene_->has_masks())
    fail("{}: the anchor's support (--anchor-support) needs the scene's masks/", scene_->root.string());
  std::vector<double> area(oe_.num_labels, 0.0);
  for (int v : scene_->train_indices()) {
    const auto m = scene_->load_mask(v);
    if (!m) continue;
    for (const uint16_t id : m->v)
      if (id < area.size()) area[id] += 1;
  }
  return mask_area_ = std::move(area);
}

const std::vector<double>& Session::rendered_area(float threshold) {
  if (!rendered_area_.empty() && rendered_threshold_ == threshold) return rendered_area_;
  const int L = oe_.num_labels;
  std::vector<double> area(L, 0.0);
  // Every label's opacity in each training view, in groups of 16 channels (a bounded buffer at any size).
  for (int v : scene_->train_indices())
    for (int k0 = 1; k0 < L; k0 += 16) {
      std::vector<int> ks;
      for (int k = k0; k < std::min(L, k0 + 16); ++k) ks.push_back(k);
      const std::vector<float> A = render_object_opacity(renderer_, *model_, camera(v), ks);
      const size_t J = ks.size(), HW = A.size() / J;
      for (size_t p = 0; p < HW; ++p)
        for (size_t j = 0; j < J; ++j) area[ks[j]] += A[p * J + j] > threshold;
    }
  rendered_threshold_ = threshold;
  return rendered_area_ = std::move(area);
}

std::vector<float> Session::object_opacity(int view, const std::vector<int>& objects) {
  const View& v = scene_->views.at(view);
  std::vector<float> A = render_object_opacity(renderer_, *model_, camera(view), objects);
  const size_t HW = size_t(v.width) * v.height, J = objects.size();
  std::vector<float> sum(HW, 0.f);
  for (size_t p = 0; p < HW; ++p)
    for (size_t j = 0; j < J; ++j) sum[p] += A[p * J + j];
  return sum;
}

eval::Mask Session::object_mask(int view, const std::vector<int>& objects, float threshold,
                                std::vector<float>* opacity) {
  std::vector<float> a = object_opacity(view, objects);
  eval::Mask m(a.size());
  for (size_t p = 0; p < a.size(); ++p) m[p] = a[p] > threshold;
  if (opacity) *opacity = std::move(a);
  return m;
}

eval::Mask Session::answer_mask(int view, const std::string& text, const QueryOptions& opt,
                                std::vector<float>* opacity) {
  return object_mask(view, ask(text, opt).chosen, opt.mask_threshold, opacity);
}

std::vector<float> Session::pixel_relevancy(int view, const std::string& text, Relevancy variant) {
  const auto& e = text_.embed(text);
  return render_relevancy(renderer_, *model_, camera(view), e.data(), text_.canonical(), variant, &oe_);
}

std::vector<std::vector<float>> Session::pixel_relevancies(int view, const std::vector<std::string>& texts,
                                                           Relevancy variant) {
  std::vector<const float*> e;
  for (const auto& t : texts) e.push_back(text_.embed(t).data());  // embed() keeps each embedding (cache)
  return render_relevancies(renderer_, *model_, camera(view), e, text_.canonical(), variant, &oe_);
}

}  // namespace hgs::query
