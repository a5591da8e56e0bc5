// Dense 2D-3D correspondences from per-view depth maps, for `hgs masks associate --depth` (associate.h).
//
// COLMAP's keypoints are sparse: a small or textureless object may hold too few 3D points to be linked across
// views. Given a z-depth map per view (from a short RGB training of the same scene, or any metric depth in the
// model's frame), every `stride`-th pixel of every view is lifted to its 3D point X = R^T (z K^-1 [x + 0.5,
// y + 0.5, 1] - t), and X is projected into every view j: it counts as observed in j at pixel (floor(u),
// floor(v)) when it lands inside the image in front of the camera and j's own depth there agrees with X's
// depth, |d_j(u, v) - z_j| <= tolerance x z_j (visibility test: a point hidden behind something in j is not
// observed there). The result is a track per lifted pixel, like a COLMAP 3D point's track, which the graph of
// masks (cluster.h) uses exactly as it uses SfM points. Brute force over view pairs: O(V^2 H W / stride^2).
#pragma once
#include <Eigen/Core>
#include <vector>

namespace hgs::masks {

struct DepthCamera {
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;            // pixel (x, y) has its centre at (x + 0.5, y + 0.5)
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();  // world -> camera
  Eigen::Vector3d t = Eigen::Vector3d::Zero();
  const float* depth = nullptr;  // [H, W] camera z; <= 0 or non-finite = no depth; null = view has none
};

struct DepthObservation {
  int view = 0;
  int x = 0, y = 0;  // pixel
};

struct DepthTracks {
  std::vector<Eigen::Vector3d> xyz;                // [P] lifted points
  std::vector<std::vector<DepthObservation>> obs;  // [P][track] views that see it (its own view first)
};

// Tracks of the pixels of every view on a `stride` grid (offset stride / 2). Points seen by no view but their
// own are left out (they link nothing). Deterministic; multi-threaded over source views.
DepthTracks depth_tracks(const std::vector<DepthCamera>& cams, int stride, double tolerance);

}  // namespace hgs::masks
