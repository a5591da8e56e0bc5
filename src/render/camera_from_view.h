// The renderer's pinhole camera of a scene view: image size, intrinsics and the world -> camera pose (R, t),
// converted from the scene's double precision to the renderer's float, and the near plane a model was trained with
// (MODEL/config.json `near_plane`; model/near_plane.h reads it).
#pragma once
#include "render/renderer.h"
#include "scene/scene.h"

namespace hgs::render {

Camera camera_from_view(const View& v, float near_plane = kDefaultNearPlane);

// The same conversion from plain arrays (a view's geometry kept elsewhere, e.g. hybrid::MaskView):
// R [3, 3] world -> camera, row-major; t [3].
Camera pinhole_camera(int width, int height, double fx, double fy, double cx, double cy, const double* R,
                      const double* t, float near_plane = kDefaultNearPlane);

}  // namespace hgs::render
