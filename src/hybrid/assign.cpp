#include "hybrid/assign.h"

#include "scene/scene.h"

#include <algorithm>
#include <cmath>

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

// z [L, D] from the sums acc [L, D] (each label's sum normalised to unit length; 0 for an absent label).
void normalise_sums(const std::vector<double>& acc, int D, int L, float* z) {
  for (int l = 0; l < L; ++l) {
    double s = 0;
    for (int d = 0; d < D; ++d) s += acc[size_t(l) * D + d] * acc[size_t(l) * D + d];
    const double inv = s > 0 ? 1.0 / std::sqrt(s) : 0.0;
    for (int d = 0; d < D; ++d) z[size_t(l) * D + d] = float(acc[size_t(l) * D + d] * inv);
  }
}

}  // namespace

void pool_reference(const float* features, const LabelMap& labels, int D, int L, float* z, float* area) {
  std::fill(area, area + L, 0.f);
  std::vector<double> acc(size_t(L) * D, 0.0);
  for (size_t p = 0; p < labels.v.size(); ++p) {
    const int l = labels.v[p];
    if (l >= L) continue;
    area[l] += 1;
    const float* f = features + p * D;
    double* a = &acc[size_t(l) * D];
    for (int d = 0; d < D; ++d) a[d] += f[d];
  }
  normalise_sums(acc, D, L, z);
}

void pool_reference_upsampled(const float* grid, int gh, int gw, const LabelMap& labels, int D, int L, float* z,
                              float* area) {
  std::fill(area, area + L, 0.f);
  std::vector<double> acc(size_t(L) * D, 0.0);
  std::vector<float> f(static_cast<size_t>(D));
  const int H = labels.height, W = labels.width;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const int l = labels.v[size_t(y) * W + x];
      if (l >= L) continue;
      area[l] += 1;
      bilinear_sample(bilinear_tap(grid, gh, gw, D, H, W, x, y), D, f.data());
      double* a = &acc[size_t(l) * D];
      for (int d = 0; d < D; ++d) a[d] += f[d];
    }
  normalise_sums(acc, D, L, z);
}

}  // namespace hgs::hybrid
