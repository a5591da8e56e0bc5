// Lift-and-reproject of depth maps into point tracks (algorithm in depth_tracks.h).
#include "masks/depth_tracks.h"

#include <cmath>

#include "core/error.h"

namespace hgs::masks {

namespace {

float depth_at(const DepthCamera& c, int x, int y) {
  const float d = c.depth[size_t(y) * c.width + x];
  return std::isfinite(d) && d > 0 ? d : 0.f;
}

}  // namespace

DepthTracks depth_tracks(const std::vector<DepthCamera>& cams, int stride, double tolerance) {
  if (stride < 1) fail("depth tracks: stride must be at least 1, got {}", stride);
  if (!(tolerance > 0)) fail("depth tracks: tolerance must be positive, got {}", tolerance);
  const int V = int(cams.size());
  std::vector<DepthTracks> per_view(V);  // tracks lifted from each source view, joined in view order
#pragma omp parallel for schedule(dynamic, 1)
  for (int i = 0; i < V; ++i) {
    const DepthCamera& ci = cams[i];
    if (!ci.depth) continue;
    DepthTracks& out = per_view[i];
    const Eigen::Matrix3d Rit = ci.R.transpose();
    for (int y = stride / 2; y < ci.height; y += stride)
      for (int x = stride / 2; x < ci.width; x += stride) {
        const float z = depth_at(ci, x, y);
        if (z <= 0) continue;
        const Eigen::Vector3d pc((x + 0.5 - ci.cx) / ci.fx * z, (y + 0.5 - ci.cy) / ci.fy * z, z);
        const Eigen::Vector3d X = Rit * (pc - ci.t);
        std::vector<DepthObservation> track = {{i, x, y}};
        for (int j = 0; j < V; ++j) {
          const DepthCamera& cj = cams[j];
          if (j == i || !cj.depth) continue;
          const Eigen::Vector3d q = cj.R * X + cj.t;
          if (!(q.z() > 1e-9)) continue;
          const double u = cj.fx * q.x() / q.z() + cj.cx, v = cj.fy * q.y() / q.z() + cj.cy;
          if (!(u >= 0 && v >= 0 && u < cj.width && v < cj.height)) continue;
          const int px = int(u), py = int(v);
          const float dj = depth_at(cj, px, py);
          if (dj > 0 && std::abs(double(dj) - q.z()) <= tolerance * q.z()) track.push_back({j, px, py});
        }
        if (track.size() < 2) continue;
        out.xyz.push_back(X);
        out.obs.push_back(std::move(track));
      }
  }
  DepthTracks all;
  for (auto& t : per_view) {
    all.xyz.insert(all.xyz.end(), t.xyz.begin(), t.xyz.end());
    for (auto& o : t.obs) all.obs.push_back(std::move(o));
  }
  return all;
}

}  // namespace hgs::masks
