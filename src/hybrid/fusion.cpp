#include "hybrid/fusion.h"

#include <cmath>

namespace hgs::hybrid {

void apply_confidence(LabelMap& labels, const std::vector<float>& conf, float tau1) {
  if (conf.empty()) return;
  for (size_t i = 0; i < labels.v.size(); ++i)
    if (conf[i] < tau1) labels.v[i] = 0;
}

std::vector<uint8_t> confident_pixels(const std::vector<float>& conf, float tau1) {
  std::vector<uint8_t> ok(conf.size());
  for (size_t i = 0; i < conf.size(); ++i) ok[i] = conf[i] >= tau1;
  return ok;
}

void hide_occluded(const float* means, int n, const MaskView& v, const float* surface_depth, int u,
                   ObservationTable& table) {
  const int U = table.num_views;
  const double* R = v.R;
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    uint16_t& l = table.label[size_t(i) * U + u];
    if (l == kNoObservation) continue;
    const double X = means[3 * i], Y = means[3 * i + 1], Z = means[3 * i + 2];
    const double z = R[6] * X + R[7] * Y + R[8] * Z + v.t[2];
    const double x = R[0] * X + R[1] * Y + R[2] * Z + v.t[0];
    const double y = R[3] * X + R[4] * Y + R[5] * Z + v.t[1];
    const int ix = static_cast<int>(v.fx * x / z + v.cx), iy = static_cast<int>(v.fy * y / z + v.cy);
    const float d = surface_depth[size_t(iy) * v.width + ix];  // in the image: observe() recorded a label
    if (d > 0 && z > d * (1 + kOcclusionTolerance)) l = kNoObservation;
  }
}

void observe(const float* means, int n, const std::vector<MaskView>& views, ObservationTable& table) {
  const int U = static_cast<int>(views.size());
  table.n = n;
  table.num_views = U;
  table.label.assign(size_t(n) * U, kNoObservation);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    const double X = means[3 * i], Y = means[3 * i + 1], Z = means[3 * i + 2];
    for (int u = 0; u < U; ++u) {
      const MaskView& v = views[u];
      const double* R = v.R;
      const double z = R[6] * X + R[7] * Y + R[8] * Z + v.t[2];
      if (!(z > 0)) continue;
      const double x = R[0] * X + R[1] * Y + R[2] * Z + v.t[0];
      const double y = R[3] * X + R[4] * Y + R[5] * Z + v.t[1];
      const double px = v.fx * x / z + v.cx, py = v.fy * y / z + v.cy;
      if (!(px >= 0 && py >= 0 && px < v.width && py < v.height)) continue;
      const int ix = static_cast<int>(px), iy = static_cast<int>(py);
      if (!v.observed.empty() && !v.observed[size_t(iy) * v.width + ix]) continue;
      table.label[size_t(i) * U + u] = v.labels.at(ix, iy);
    }
  }
}

}  // namespace hgs::hybrid
