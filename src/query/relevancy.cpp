// LERF relevancy. The map version normalises the query and canonical vectors once, then takes blocks of
// 4096 rows: one float GEMM (rows x D times D x (1 + #canonical)) and the row norms give every cosine;
// p_i uses the logistic form 1 / (1 + exp(T (s_i - s_q))), which cannot overflow.
#include "query/relevancy.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace hgs::query {

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

}  // namespace

void check_canonical(const std::vector<std::vector<float>>& canonical, int dim) {
  if (dim <= 0) fail("eval: relevancy needs a positive embedding dimension, got {}", dim);
  if (canonical.empty()) fail("eval: the LERF relevancy needs at least one canonical phrase embedding");
  for (size_t i = 0; i < canonical.size(); ++i)
    if (canonical[i].size() != size_t(dim))
      fail("eval: canonical phrase embedding {} has dimension {}, expected {}", i, canonical[i].size(), dim);
}

float lerf_relevancy_from_cosines(double sq, const double* sc, size_t m, float t) {
  double r = 1.0;
  for (size_t i = 0; i < m; ++i) r = std::min(r, 1.0 / (1.0 + std::exp(double(t) * (sc[i] - sq))));
  return static_cast<float>(r);
}

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
  return lerf_relevancy_from_cosines(sq, sc.data(), sc.size(), temperature);
}

std::vector<float> lerf_relevancy_map(const float* features, size_t n, int dim, const float* query,
                                      const std::vector<std::vector<float>>& canonical, float temperature, int stride) {
  if (stride == 0) stride = dim;
  if (stride < dim) fail("eval: relevancy row stride {} is below the feature dimension {}", stride, dim);
  check_canonical(canonical, dim);
  const int m = static_cast<int>(canonical.size());
  // Columns of `dirs`: the unit query, then the unit canonical vectors. [D, 1 + m]
  Eigen::MatrixXf dirs(dim, 1 + m);
  auto uq = unit(query, dim);
  dirs.col(0) = Eigen::Map<const Eigen::VectorXf>(uq.data(), dim);
  for (int i = 0; i < m; ++i) {
    auto u = unit(canonical[i].data(), dim);
    dirs.col(1 + i) = Eigen::Map<const Eigen::VectorXf>(u.data(), dim);
  }
  std::vector<float> out(n);
  // Blocks of rows: dots = F_block [B, D] x dirs [D, 1 + m] (float GEMM), norms in float.
  constexpr size_t kBlock = 4096;
  const long long nblocks = static_cast<long long>((n + kBlock - 1) / kBlock);
#pragma omp parallel for schedule(dynamic)
  for (long long blk = 0; blk < nblocks; ++blk) {
    const size_t p0 = size_t(blk) * kBlock, rows = std::min(kBlock, n - p0);
    Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>, 0, Eigen::OuterStride<>> F(
        features + p0 * stride, static_cast<Eigen::Index>(rows), dim, Eigen::OuterStride<>(stride));
    const Eigen::MatrixXf dots = F * dirs;             // [B, 1 + m]
    const Eigen::VectorXf norms = F.rowwise().norm();  // [B]
    std::vector<double> sc(m);
    for (size_t r = 0; r < rows; ++r) {
      const double ne = norms[r];
      const double sq = ne > 0 ? dots(r, 0) / ne : 0.0;
      for (int i = 0; i < m; ++i) sc[i] = ne > 0 ? dots(r, 1 + i) / ne : 0.0;
      out[p0 + r] = lerf_relevancy_from_cosines(sq, sc.data(), m, temperature);
    }
  }
  return out;
}

}  // namespace hgs::query
