// Adam update loops. Parameters whose columns share one learning rate are updated as a flat array (SIMD
// friendly); others (SH: DC vs higher coefficients) row by row.
#include "train/adam.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace hgs::train {

AdamParam& Adam::add(const std::string& name, int dim, int n, float lr) {
  if (find(name)) fail("adam: parameter '{}' added twice", name);
  AdamParam p;
  p.name = name;
  p.dim = dim;
  p.set_lr(lr);
  p.m.assign(size_t(n) * dim, 0.f);
  p.v.assign(size_t(n) * dim, 0.f);
  params.push_back(std::move(p));
  return params.back();
}

AdamParam* Adam::find(const std::string& name) {
  for (auto& p : params)
    if (p.name == name) return &p;
  return nullptr;
}

AdamParam& Adam::get(const std::string& name) {
  AdamParam* p = find(name);
  if (!p) fail("adam: no parameter '{}'", name);
  return *p;
}

void Adam::update(AdamParam& p, float* value, const float* grad, int n) const {
  const size_t total = size_t(n) * p.dim;
  if (p.m.size() != total) fail("adam: parameter '{}' has moments for {} values, got {}", p.name, p.m.size(), total);
  const double t = double(std::max(1L, step_count));
  const float bc1 = float(1.0 - std::pow(double(beta1), t));
  const float inv_sqrt_bc2 = float(1.0 / std::sqrt(1.0 - std::pow(double(beta2), t)));
  const float b1 = beta1, b2 = beta2, e = eps;
  float* m = p.m.data();
  float* v = p.v.data();
  bool uniform = std::all_of(p.lr.begin(), p.lr.end(), [&](float l) { return l == p.lr[0]; });
  if (uniform) {
    const float step = p.lr[0] / bc1;
#pragma omp parallel for simd schedule(static)
    for (size_t i = 0; i < total; ++i) {
      float g = grad[i];
      float mi = b1 * m[i] + (1 - b1) * g;
      float vi = b2 * v[i] + (1 - b2) * g * g;
      m[i] = mi;
      v[i] = vi;
      value[i] -= step * mi / (std::sqrt(vi) * inv_sqrt_bc2 + e);
    }
  } else {
    const int d = p.dim;
    float steps[256];
    if (d > 256) fail("adam: parameter '{}' has {} columns with different rates (max 256)", p.name, d);
    for (int c = 0; c < d; ++c) steps[c] = p.lr[c] / bc1;
#pragma omp parallel for schedule(static)
    for (long r = 0; r < n; ++r) {
      const size_t o = size_t(r) * d;
#pragma omp simd
      for (int c = 0; c < d; ++c) {
        float g = grad[o + c];
        float mi = b1 * m[o + c] + (1 - b1) * g;
        float vi = b2 * v[o + c] + (1 - b2) * g * g;
        m[o + c] = mi;
        v[o + c] = vi;
        value[o + c] -= steps[c] * mi / (std::sqrt(vi) * inv_sqrt_bc2 + e);
      }
    }
  }
}

void Adam::gather(const std::vector<int>& src, const std::vector<char>& fresh) {
  std::vector<float> tm, tv;
  for (auto& p : params) {
    const int d = p.dim;
    tm.assign(src.size() * d, 0.f);
    tv.assign(src.size() * d, 0.f);
    for (size_t i = 0; i < src.size(); ++i) {
      if (!fresh.empty() && fresh[i]) continue;
      std::copy_n(p.m.data() + size_t(src[i]) * d, d, tm.data() + i * d);
      std::copy_n(p.v.data() + size_t(src[i]) * d, d, tv.data() + i * d);
    }
    p.m.swap(tm);
    p.v.swap(tv);
  }
}

void Adam::reset_moments(const std::string& name) {
  AdamParam& p = get(name);
  std::fill(p.m.begin(), p.m.end(), 0.f);
  std::fill(p.v.begin(), p.v.end(), 0.f);
}

}  // namespace hgs::train
