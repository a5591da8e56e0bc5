// MODEL/config.json's near plane (model/near_plane.h): read beside the PLY, 0.01 without a config or key, one-line
// errors naming the file for bad values; and render::camera_from_view culls at the plane it is given.
#include <gtest/gtest.h>

#include "core/fs.h"
#include "expect_error.h"
#include "model/gaussian_model.h"
#include "model/near_plane.h"
#include "model/render_inputs.h"
#include "render/camera_from_view.h"
#include "test_util.h"

namespace hgs {
namespace {

TEST(NearPlane, ReadBesideThePly) {
  test::TempDir d;
  const auto ply = d / "point_cloud.ply";                       // need not exist: only the config beside it is read
  EXPECT_EQ(model_near_plane(ply), render::kDefaultNearPlane);  // no config.json
  atomic_write_text(d / "config.json", R"({"method": "rgb"})");
  EXPECT_EQ(model_near_plane(ply), render::kDefaultNearPlane);  // trained before the key existed
  atomic_write_text(d / "config.json", R"({"near_plane": 0.2})");
  EXPECT_EQ(model_near_plane(ply), 0.2f);
  atomic_write_text(d / "config.json", R"({"near_plane": "near"})");
  EXPECT_FILE_ERROR(model_near_plane(ply), d / "config.json", "near_plane");
  atomic_write_text(d / "config.json", R"({"near_plane": -1})");
  EXPECT_FILE_ERROR(model_near_plane(ply), d / "config.json", "near plane must be a number > 0");
  atomic_write_text(d / "config.json", R"({"near_plane": 0.2)");
  EXPECT_FILE_ERROR(model_near_plane(ply), d / "config.json", "invalid JSON");
}

TEST(NearPlane, CameraCullsNearerGaussians) {
  // One Gaussian on the optical axis 0.1 in front of an identity camera: drawn at the default plane, culled at 0.2.
  GaussianModel m;
  m.sh_degree = 0;
  m.resize(1);
  m.mean = {0.f, 0.f, 0.1f};
  m.log_scale = {-5.f, -5.f, -5.f};
  m.quat = {1.f, 0.f, 0.f, 0.f};
  m.opacity_logit = {4.f};
  m.sh = {1.f, 1.f, 1.f};
  View v;
  v.width = 16, v.height = 12, v.fx = v.fy = 20, v.cx = 8, v.cy = 6;
  render::GaussianRenderer r;
  render::RenderSettings rs;
  render::RenderOutputs out;
  const render::GaussianInputs in = render_inputs(m);
  r.forward(render::camera_from_view(v), in, rs, out);
  EXPECT_EQ(out.num_visible, 1);
  r.forward(render::camera_from_view(v, 0.2f), in, rs, out);
  EXPECT_EQ(out.num_visible, 0);
  for (float a : out.alpha) EXPECT_EQ(a, 0.f);
}

}  // namespace
}  // namespace hgs
