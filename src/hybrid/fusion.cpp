#include "hybrid/fusion.h"

#include <atomic>
#include <cmath>

#include "core/error.h"

namespace hgs::hybrid {

void apply_confidence(LabelMap& labels, const std::vector<float>& conf, float tau1) {
  if (conf.empty()) return;
  if (conf.size() != labels.v.size())
    fail("hybrid: a confidence map of {} pixels for a mask of {} pixels", conf.size(), labels.v.size());
  for (size_t i = 0; i < labels.v.size(); ++i)
    if (conf[i] < tau1) labels.v[i] = 0;
}

std::vector<uint8_t> confident_pixels(const std::vector<float>& conf, float tau1) {
  std::vector<uint8_t> ok(conf.size());
  for (size_t i = 0; i < conf.size(); ++i) ok[i] = conf[i] >= tau1;
  return ok;
}

std::vector<uint8_t> gap_pixels(const LabelMap& labels, const std::string& gaps) {
  if (gaps == "background" || labels.v.empty()) return {};
  std::vector<uint8_t> gap(labels.v.size());
  size_t unlabelled = 0;
  for (size_t i = 0; i < gap.size(); ++i) unlabelled += gap[i] = labels.v[i] == 0;
  if (gaps == "auto" && double(gap.size() - unlabelled) < kGapsCoverage * double(gap.size())) return {};
  return gap;
}

namespace {

// Eq. 3 for one centre in one view: camera-space depth z and, when z > 0, z >= near and the projection lies in
// the image, the pixel (ix, iy). Returns false otherwise (V_{n,u} = 0). Shared by observe() and hide_occluded(),
// which must agree on the pixel.
inline bool project_centre(const MaskView& v, const float* c, double near, double& z, int& ix, int& iy) {
  const double X = c[0], Y = c[1], Z = c[2];
  const double* R = v.R;
  z = R[6] * X + R[7] * Y + R[8] * Z + v.t[2];
  if (!(z > 0 && z >= near)) return false;
  const double x = R[0] * X + R[1] * Y + R[2] * Z + v.t[0];
  const double y = R[3] * X + R[4] * Y + R[5] * Z + v.t[1];
  const double px = v.fx * x / z + v.cx, py = v.fy * y / z + v.cy;
  if (!(px >= 0 && py >= 0 && px < v.width && py < v.height)) return false;
  ix = static_cast<int>(px);
  iy = static_cast<int>(py);
  return true;
}

}  // namespace

void hide_occluded(const float* means, int n, const MaskView& v, const float* surface_depth, int u,
                   ObservationTable& table) {
  const int U = table.num_views;
  // On demand (demand_chunk): the work is the observed Gaussians', which cluster by index once densification has
  // appended its clones (a static split left threads idle; occlusion_pixels likewise).
#pragma omp parallel for schedule(dynamic, demand_chunk(n, 128))
  for (int i = 0; i < n; ++i) {
    uint16_t& l = table.label[size_t(i) * U + u];
    double z;
    int ix, iy;
    if (l == kNoObservation || !project_centre(v, means + 3 * i, 0.0, z, ix, iy)) continue;  // observed: z >= near
    const float d = surface_depth[size_t(iy) * v.width + ix];
    if (d > 0 && z > d * (1 + kOcclusionTolerance)) l = kNoObservation;
  }
}

void occlusion_pixels(const float* means, int n, const MaskView& v, int u, const ObservationTable& table,
                      uint8_t* chosen) {
  const int U = table.num_views;
#pragma omp parallel for schedule(dynamic, demand_chunk(n, 128))
  for (int i = 0; i < n; ++i) {
    double z;
    int ix, iy;
    // hide_occluded's condition, so it reads no pixel left out here
    if (table.label[size_t(i) * U + u] == kNoObservation || !project_centre(v, means + 3 * i, 0.0, z, ix, iy)) continue;
    std::atomic_ref<uint8_t>(chosen[size_t(iy) * v.width + ix]).store(1, std::memory_order_relaxed);  // shared pixels
  }
}

void observe(const float* means, int n, const std::vector<MaskView>& views, ObservationTable& table,
             double near_plane) {
  const int U = static_cast<int>(views.size());
  table.n = n;
  table.num_views = U;
  // Every entry is written by the loop (no serial fill first: at 300k Gaussians and 42 views that is 25 MB, a
  // serial pass every rebuild); resize fills only when the Gaussians grew since the last rebuild.
  table.label.resize(size_t(n) * U);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    for (int u = 0; u < U; ++u) {
      const MaskView& v = views[u];
      uint16_t l = kNoObservation;
      double z;
      int ix, iy;
      if (project_centre(v, means + 3 * i, near_plane, z, ix, iy) &&
          (v.observed.empty() || v.observed[size_t(iy) * v.width + ix]))
        l = v.labels.at(ix, iy);
      table.label[size_t(i) * U + u] = l;
    }
  }
}

}  // namespace hgs::hybrid
