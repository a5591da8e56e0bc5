// Scene view -> render::Camera (see camera_from_view.h).
#include "render/camera_from_view.h"

namespace hgs::render {

Camera pinhole_camera(int width, int height, double fx, double fy, double cx, double cy, const double* R,
                      const double* t, float near_plane) {
  Camera c;
  c.near_plane = near_plane;
  c.width = width;
  c.height = height;
  c.fx = float(fx);
  c.fy = float(fy);
  c.cx = float(cx);
  c.cy = float(cy);
  for (int k = 0; k < 9; ++k) c.R[k] = float(R[k]);
  for (int k = 0; k < 3; ++k) c.t[k] = float(t[k]);
  return c;
}

Camera camera_from_view(const View& v, float near_plane) {
  double R[9];
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) R[r * 3 + k] = v.R(r, k);
  return pinhole_camera(v.width, v.height, v.fx, v.fy, v.cx, v.cy, R, v.t.data(), near_plane);
}

}  // namespace hgs::render
