// GaussianModel bookkeeping (fields, resize, row gather) and the 3DGS initialisation from SfM points.
#include "model/gaussian_model.h"

#include <algorithm>

#include <immintrin.h>

#include "core/error.h"
#include "core/half.h"
#include "model/knn.h"

namespace hgs {

float ExtraGroup::value(size_t k) const { return f16 ? half_to_float(half[k]) : data[k]; }

void ExtraGroup::row(size_t i, float* out) const {
  const size_t o = i * size_t(dim);
  if (!f16) {
    std::copy_n(data.data() + o, dim, out);
    return;
  }
  // Callers walk rows in increasing order, often skipping some (SCL's passes over the rows a view touched): ask
  // for the row two further on now, so that its lines arrive while this one and the next are used (2 B a value,
  // whole lines; the hardware prefetcher stops at page boundaries, 4 rows of D = 512).
  const size_t ahead = o + 2 * size_t(dim);
  if (ahead + size_t(dim) <= half.size())
    for (size_t b = 0; b < size_t(dim) * 2; b += 64)
      __builtin_prefetch(reinterpret_cast<const char*>(half.data() + ahead) + b);
  int c = 0;
  for (; c + 8 <= dim; c += 8)
    _mm256_storeu_ps(out + c, _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(half.data() + o + c))));
  for (; c < dim; ++c) out[c] = half_to_float(half[o + c]);
}

std::vector<float> ExtraGroup::to_float() const {
  if (!f16) return data;
  std::vector<float> out(half.size());
  const size_t rows = dim > 0 ? half.size() / size_t(dim) : 0;
#pragma omp parallel for schedule(static)
  for (long i = 0; i < long(rows); ++i) row(size_t(i), out.data() + size_t(i) * dim);
  return out;
}

std::vector<Field> GaussianModel::fields() {
  std::vector<Field> f = {{"mean", 3, &mean},
                          {"log_scale", 3, &log_scale},
                          {"quat", 4, &quat},
                          {"opacity", 1, &opacity_logit},
                          {"sh", sh_stride() * 3, &sh}};
  for (auto& e : extras)
    if (!e.f16) f.push_back({e.name, e.dim, &e.data});
  return f;
}

void GaussianModel::resize(int count) {
  n = count;
  for (auto& f : fields()) f.data->assign(size_t(count) * f.dim, 0.f);
  for (auto& e : extras)
    if (e.f16) e.half.assign(size_t(count) * e.dim, 0);
  for (int i = 0; i < count; ++i) quat[size_t(i) * 4] = 1.f;
}

ExtraGroup& GaussianModel::add_extra(const std::string& name, int dim, float fill, bool f16) {
  if (find_extra(name)) fail("model: extra channel group '{}' already exists", name);
  if (dim < 1) fail("model: extra channel group '{}' needs dim >= 1", name);
  ExtraGroup e;
  e.name = name;
  e.dim = dim;
  e.f16 = f16;
  if (f16) e.half.assign(size_t(n) * dim, float_to_half(fill));
  else e.data.assign(size_t(n) * dim, fill);
  extras.push_back(std::move(e));
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
  for (auto& f : fields()) gather_rows(*f.data, f.dim, src);
  for (auto& e : extras)
    if (e.f16) gather_rows(e.half, e.dim, src);
  n = int(src.size());
}

void GaussianModel::validate(const std::string& where) const {
  if (sh_degree < 0 || sh_degree > 3) fail("{}: SH degree {} is outside 0..3", where, sh_degree);
  auto& self = const_cast<GaussianModel&>(*this);
  for (auto& f : self.fields())
    if (f.data->size() != size_t(n) * f.dim)
      fail("{}: array '{}' has {} values, expected {} x {}", where, f.name, f.data->size(), n, f.dim);
  for (auto& e : extras)
    if (e.f16 && (e.half.size() != size_t(n) * e.dim || !e.data.empty()))
      fail("{}: half-precision array '{}' has {} values, expected {} x {}", where, e.name, e.half.size(), n, e.dim);
}

GaussianModel init_from_points(const std::vector<Eigen::Vector3f>& points, const std::vector<Eigen::Vector3f>& colors,
                               int sh_degree) {
  if (points.size() < 4)
    fail("init: the scene has {} SfM points; at least 4 are needed to initialise Gaussians", points.size());
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

}  // namespace hgs
