// LERF relevancy. The map version normalises the query and canonical vectors once, then per row needs one
// norm and (1 + #canonical) dot products; p_i uses the logistic form 1 / (1 + exp(T (s_i - s_q))), which
// cannot overflow.
#include "eval/relevancy.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace hgs::eval {

namespace {

double dot(const float* a, const float* b, int d) {
  double s = 0;
  for (int k = 0; k < d; ++k) s += double(a[k]) * b[k];
  return s;
}

std::vector<float> unit(const float* v, int d) {
  const double n = std::sqrt(dot(v, v, d));
  std::vector<float> u(d, 0.f);
  if (n > 0)
    for (int k = 0; k < d; ++k) u[k] = static_cast<float>(v[k] / n);
  return u;
}

void check_canonical(const std::vector<std::vector<float>>& canonical, int dim) {
  if (dim <= 0) fail("eval: relevancy needs a positive embedding dimension, got {}", dim);
  if (canonical.empty()) fail("eval: the LERF relevancy needs at least one canonical phrase embedding");
  for (size_t i = 0; i < canonical.size(); ++i)
    if (canonical[i].size() != size_t(dim))
      fail("eval: canonical phrase embedding {} has dimension {}, expected {}", i, canonical[i].size(), dim);
}

float relevancy_from_cos(double sq, const double* sc, size_t m, float t) {
  double r = 1.0;
  for (size_t i = 0; i < m; ++i) r = std::min(r, 1.0 / (1.0 + std::exp(double(t) * (sc[i] - sq))));
  return static_cast<float>(r);
}

}  // namespace

float cosine(const float* a, const float* b, int dim) {
  const double na = dot(a, a, dim), nb = dot(b, b, dim);
  if (na <= 0 || nb <= 0) return 0.f;
  return static_cast<float>(dot(a, b, dim) / std::sqrt(na * nb));
}

float lerf_relevancy(const float* e, const float* query, const std::vector<std::vector<float>>& canonical, int dim,
                     float temperature) {
  check_canonical(canonical, dim);
  const double sq = cosine(e, query, dim);
  std::vector<double> sc(canonical.size());
  for (size_t i = 0; i < canonical.size(); ++i) sc[i] = cosine(e, canonical[i].data(), dim);
  return relevancy_from_cos(sq, sc.data(), sc.size(), temperature);
}

std::vector<float> lerf_relevancy_map(const float* features, size_t n, int dim, const float* query,
                                      const std::vector<std::vector<float>>& canonical, float temperature) {
  check_canonical(canonical, dim);
  const size_t m = canonical.size();
  // Rows of `dirs`: the unit query, then the unit canonical vectors. [1 + m, D]
  std::vector<float> dirs;
  dirs.reserve((1 + m) * dim);
  auto uq = unit(query, dim);
  dirs.insert(dirs.end(), uq.begin(), uq.end());
  for (auto& c : canonical) {
    auto u = unit(c.data(), dim);
    dirs.insert(dirs.end(), u.begin(), u.end());
  }
  std::vector<float> out(n);
#pragma omp parallel
  {
    std::vector<double> s(1 + m);
#pragma omp for schedule(static)
    for (long long p = 0; p < static_cast<long long>(n); ++p) {
      const float* e = features + size_t(p) * dim;
      const double ne = std::sqrt(dot(e, e, dim));
      for (size_t i = 0; i <= m; ++i) s[i] = ne > 0 ? dot(e, &dirs[i * dim], dim) / ne : 0.0;
      out[p] = relevancy_from_cos(s[0], s.data() + 1, m, temperature);
    }
  }
  return out;
}

}  // namespace hgs::eval
