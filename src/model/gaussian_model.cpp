// GaussianModel bookkeeping (fields, resize, row gather) and the 3DGS initialisation from SfM points.
#include "model/gaussian_model.h"

#include <algorithm>

#include "core/error.h"
#include "model/knn.h"

namespace hgs {

std::vector<Field> GaussianModel::fields() {
  std::vector<Field> f = {{"mean", 3, &mean},
                          {"log_scale", 3, &log_scale},
                          {"quat", 4, &quat},
                          {"opacity", 1, &opacity_logit},
                          {"sh", sh_stride() * 3, &sh}};
  for (auto& e : extras) f.push_back({e.name, e.dim, &e.data});
  return f;
}

void GaussianModel::resize(int count) {
  n = count;
  for (auto& f : fields()) f.data->assign(size_t(count) * f.dim, 0.f);
  for (int i = 0; i < count; ++i) quat[size_t(i) * 4] = 1.f;
}

ExtraGroup& GaussianModel::add_extra(const std::string& name, int dim, float fill) {
  if (find_extra(name)) fail("model: extra channel group '{}' already exists", name);
  if (dim < 1) fail("model: extra channel group '{}' needs dim >= 1", name);
  extras.push_back({name, dim, std::vector<float>(size_t(n) * dim, fill)});
  return extras.back();
}

ExtraGroup* GaussianModel::find_extra(const std::string& name) {
  for (auto& e : extras)
    if (e.name == name) return &e;
  return nullptr;
}

const ExtraGroup* GaussianModel::find_extra(const std::string& name) const {
  for (auto& e : extras)
    if (e.name == name) return &e;
  return nullptr;
}

bool is_compaction(const std::vector<int>& src, int n) {
  if (src.size() > size_t(n)) return false;
  for (size_t i = 0; i < src.size(); ++i)
    if (src[i] < int(i) || src[i] >= n || (i > 0 && src[i] <= src[i - 1])) return false;
  return true;
}

void GaussianModel::gather(const std::vector<int>& src) {
  if (is_compaction(src, n)) {
    // Pruning: rows move only towards the front, so the arrays are compacted in place (no second copy of the
    // language embeddings, which dominate memory; the capacity is kept for later growth).
    for (auto& f : fields()) {
      float* d = f.data->data();
      for (size_t i = 0; i < src.size(); ++i)
        if (src[i] != int(i)) std::copy_n(d + size_t(src[i]) * f.dim, f.dim, d + i * f.dim);
      f.data->resize(src.size() * f.dim);
    }
    n = int(src.size());
    return;
  }
  std::vector<float> tmp;
  for (auto& f : fields()) {
    tmp.resize(src.size() * f.dim);
    const float* s = f.data->data();
    for (size_t i = 0; i < src.size(); ++i)
      std::copy_n(s + size_t(src[i]) * f.dim, f.dim, tmp.data() + i * f.dim);
    f.data->swap(tmp);
  }
  n = int(src.size());
}

void GaussianModel::validate(const std::string& where) const {
  if (sh_degree < 0 || sh_degree > 3) fail("{}: SH degree {} is outside 0..3", where, sh_degree);
  auto& self = const_cast<GaussianModel&>(*this);
  for (auto& f : self.fields())
    if (f.data->size() != size_t(n) * f.dim)
      fail("{}: array '{}' has {} values, expected {} x {}", where, f.name, f.data->size(), n, f.dim);
}

GaussianModel init_from_points(const std::vector<Eigen::Vector3f>& points, const std::vector<Eigen::Vector3f>& colors,
                               int sh_degree) {
  if (points.size() < 4) fail("init: the scene has {} SfM points; at least 4 are needed to initialise Gaussians", points.size());
  if (colors.size() != points.size()) fail("init: {} points but {} colours", points.size(), colors.size());
  GaussianModel m;
  m.sh_degree = sh_degree;
  m.resize(int(points.size()));
  std::vector<float> d2 = knn_mean_sq_dist(points, 3);
  const int S = m.sh_stride();
  const float op = inverse_sigmoid(0.1f);
  for (int i = 0; i < m.n; ++i) {
    for (int c = 0; c < 3; ++c) {
      m.mean[size_t(i) * 3 + c] = points[i][c];
      m.sh[size_t(i) * S * 3 + c] = rgb_to_sh(colors[i][c]);
    }
    float ls = std::log(std::sqrt(std::max(d2[i], 1e-7f)));
    for (int c = 0; c < 3; ++c) m.log_scale[size_t(i) * 3 + c] = ls;
    m.opacity_logit[i] = op;
  }
  return m;
}

float scene_extent(const Scene& scene, const std::vector<int>& views) {
  std::vector<int> idx = views;
  if (idx.empty())
    for (auto& v : scene.views) idx.push_back(v.index);
  if (idx.empty()) return 1.f;
  Eigen::Vector3d c = Eigen::Vector3d::Zero();
  for (int i : idx) c += scene.views[i].camera_center();
  c /= double(idx.size());
  double r = 0;
  for (int i : idx) r = std::max(r, (scene.views[i].camera_center() - c).norm());
  if (r <= 0) r = 1.0 / 1.1;  // a single camera: unit extent
  return float(r * 1.1);
}

render::GaussianInputs render_inputs(const GaussianModel& m) {
  render::GaussianInputs in;
  in.n = m.n;
  in.mean = m.mean.data();
  in.log_scale = m.log_scale.data();
  in.quat = m.quat.data();
  in.opacity_logit = m.opacity_logit.data();
  in.sh = m.sh.data();
  in.sh_stride = m.sh_stride();
  in.sh_degree = m.sh_degree;
  return in;
}

}  // namespace hgs
