#include "hybrid/assign.h"

#include <algorithm>
#include <cmath>

#include "scene/scene.h"

namespace hgs::hybrid {

void single_view_assignment(const ObservationTable& tab, int L, float* q) {
#pragma omp parallel for schedule(static)
  for (int n = 0; n < tab.n; ++n) {
    const uint16_t* lab = &tab.label[size_t(n) * tab.num_views];
    for (int u = 0; u < tab.num_views; ++u) {
      if (lab[u] == kNoObservation || lab[u] >= L) continue;
      float* qn = q + size_t(n) * L;
      std::fill(qn, qn + L, 0.f);
      qn[lab[u]] = 1.f;
      break;
    }
  }
}

namespace {

// Eq. 9's pooling with each pixel's features from row(p, buf) (a pointer to its D values; buf [D] is scratch):
// per label the sum over its pixels in pixel order (double), normalised to unit length (0 for an absent label).
template <class Row>
void pool_rows(const LabelMap& labels, int D, int L, Row&& row, float* z, float* area) {
  std::fill(area, area + L, 0.f);
  std::vector<double> acc(size_t(L) * D, 0.0);
  std::vector<float> buf(static_cast<size_t>(D));
  for (size_t p = 0; p < labels.v.size(); ++p) {
    const int l = labels.v[p];
    if (l >= L) continue;
    area[l] += 1;
    const float* f = row(p, buf.data());
    double* a = &acc[size_t(l) * D];
    for (int d = 0; d < D; ++d) a[d] += f[d];
  }
  for (int l = 0; l < L; ++l) {
    double s = 0;
    for (int d = 0; d < D; ++d) s += acc[size_t(l) * D + d] * acc[size_t(l) * D + d];
    const double inv = s > 0 ? 1.0 / std::sqrt(s) : 0.0;
    for (int d = 0; d < D; ++d) z[size_t(l) * D + d] = float(acc[size_t(l) * D + d] * inv);
  }
}

}  // namespace

void pool_reference(const float* features, const LabelMap& labels, int D, int L, float* z, float* area) {
  pool_rows(
      labels, D, L, [&](size_t p, float*) { return features + p * D; }, z, area);
}

void pool_reference_upsampled(const float* grid, int gh, int gw, const LabelMap& labels, int D, int L, float* z,
                              float* area) {
  const int H = labels.height, W = labels.width;
  pool_rows(
      labels, D, L, [&](size_t p, float* buf) { return bilinear_pixel(grid, gh, gw, D, H, W, p, buf); }, z, area);
}

}  // namespace hgs::hybrid
