// masks::depth_tracks (depth_tracks.h): pixels lifted by their depth and re-projected into the other views,
// checked against a brute-force projection of each lifted point on a hand-made two-camera scene, with an
// occluder that one view sees and the other does not.
#include <gtest/gtest.h>

#include <cmath>
#include <set>
#include <tuple>

#include "core/error.h"
#include "masks/depth_tracks.h"

using namespace hgs;
using namespace hgs::masks;

namespace {

constexpr int kW = 20, kH = 12;

// Camera at centre C looking down +z (R = I, t = -C), fx = fy = 10.
DepthCamera camera(double cx_world, std::vector<float>& depth) {
  DepthCamera c;
  c.width = kW, c.height = kH, c.fx = c.fy = 10, c.cx = 10, c.cy = 6;
  c.t = Eigen::Vector3d(-cx_world, 0, 0);
  c.depth = depth.data();
  return c;
}

TEST(DepthTracks, LiftedPixelsLandWhereTheirPointProjectsAndOcclusionHides) {
  // A wall at z = 10 seen by two cameras 1 apart in x (the second sees the wall shifted by 1 px). In camera 1 a
  // box at z = 5 covers pixels x in [4, 8): wall points behind it are not seen there; the box's own pixels lift
  // to z = 5 points, which camera 0 (whose depth there is the wall's 10) does not see.
  std::vector<float> d0(kW * kH, 10.f), d1(kW * kH, 10.f);
  for (int y = 0; y < kH; ++y)
    for (int x = 4; x < 8; ++x) d1[y * kW + x] = 5.f;
  d0[3 * kW + 15] = 0.f;  // a hole in camera 0's depth: nothing lifts from there
  const std::vector<DepthCamera> cams = {camera(0, d0), camera(1, d1)};
  const DepthTracks t = depth_tracks(cams, 1, 0.02);
  ASSERT_EQ(t.xyz.size(), t.obs.size());
  std::set<std::tuple<int, int, int, int, int>> got;  // (source view, x, y, other view's x, y)
  for (size_t p = 0; p < t.obs.size(); ++p) {
    ASSERT_EQ(t.obs[p].size(), 2u) << "two views";
    const auto& a = t.obs[p][0];
    const auto& b = t.obs[p][1];
    // Brute force: the lifted point is where the source pixel's ray meets its depth.
    const DepthCamera& ca = cams[a.view];
    const double z = ca.depth[a.y * kW + a.x];
    const Eigen::Vector3d X((a.x + 0.5 - 10) / 10 * z - ca.t.x(), (a.y + 0.5 - 6) / 10 * z, z);
    EXPECT_NEAR((t.xyz[p] - X).norm(), 0, 1e-9);
    got.insert({a.view, a.x, a.y, b.x, b.y});
  }
  std::set<std::tuple<int, int, int, int, int>> want;
  for (int y = 0; y < kH; ++y)
    for (int x = 0; x < kW; ++x) {
      // View 0 -> 1: the wall point at pixel x lands at x - 1 in camera 1, seen unless the box is there.
      if (!(x == 15 && y == 3) && x - 1 >= 0 && !(x - 1 >= 4 && x - 1 < 8)) want.insert({0, x, y, x - 1, y});
      // View 1 -> 0: wall pixels land at x + 1; box pixels (z = 5) land at x + 2 where camera 0 sees the wall.
      if (!(x >= 4 && x < 8) && x + 1 < kW && !(x + 1 == 15 && y == 3)) want.insert({1, x, y, x + 1, y});
    }
  EXPECT_EQ(got, want);
}

TEST(DepthTracks, StrideSamplesAGridAndBadArgumentsAreErrors) {
  std::vector<float> d0(kW * kH, 10.f), d1(kW * kH, 10.f);
  const std::vector<DepthCamera> cams = {camera(0, d0), camera(1, d1)};
  const DepthTracks t = depth_tracks(cams, 4, 0.02);
  for (auto& o : t.obs) {
    EXPECT_EQ(o[0].x % 4, 2);
    EXPECT_EQ(o[0].y % 4, 2);
  }
  EXPECT_EQ(t.obs.size(), size_t(2 * 5 * 3));  // 5 x 3 grid pixels per view, all seen by the other view
  EXPECT_THROW(depth_tracks(cams, 0, 0.02), hgs::Error);
  EXPECT_THROW(depth_tracks(cams, 1, 0.0), hgs::Error);
  // A view without depth lifts nothing and sees nothing.
  std::vector<DepthCamera> one = cams;
  one[1].depth = nullptr;
  EXPECT_TRUE(depth_tracks(one, 1, 0.02).obs.empty());
}

}  // namespace
