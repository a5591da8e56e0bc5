// Scene view -> render::Camera (see camera_from_view.h).
#include "render/camera_from_view.h"

namespace hgs::render {

Camera camera_from_view(const View& v, float near_plane) {
  Camera c;
  c.near_plane = near_plane;
  c.width = v.width;
  c.height = v.height;
  c.fx = float(v.fx);
  c.fy = float(v.fy);
  c.cx = float(v.cx);
  c.cy = float(v.cy);
  for (int r = 0; r < 3; ++r) {
    for (int k = 0; k < 3; ++k) c.R[r * 3 + k] = float(v.R(r, k));
    c.t[r] = float(v.t[r]);
  }
  return c;
}

}  // namespace hgs::render
