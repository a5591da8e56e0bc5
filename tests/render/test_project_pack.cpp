// The projection's pack path (render/project_pack.h: 8 Gaussians per vector, the float renderer's) against the
// scalar path of project.h: on double packs (every lane the scalar double functions) the same culling and the same
// values to rounding; on float packs (the production path, exp by simd::vexp) against the scalar double
// projection to float accuracy. Counts not a multiple of 8 (the padded last pack), Gaussians behind the camera, at
// the near plane, off the image, outside the Jacobian clamp and with a zero quaternion are in the scene.
#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "render/project_pack.h"
#include "render_ref.h"

namespace hgs::render::test {
namespace {

// random_scene plus hand-made edge cases, in double.
Scene pack_scene(int n, uint32_t seed) {
  Scene s = random_scene(n, 64, 48, seed);
  // a zero quaternion, a Gaussian whose centre is exactly at the camera's depth 0, a far one off the image
  for (int k = 0; k < 4; ++k) s.quat[4 * 3 + k] = 0;
  for (int k = 0; k < 3; ++k)
    s.mean[3 * 5 + k] =
        -(s.cam.R[k] * s.cam.t[0] + s.cam.R[3 + k] * s.cam.t[1] + s.cam.R[6 + k] * s.cam.t[2]);  // the camera centre
  s.mean[3 * 6] += 1e3;
  return s;
}

double rel(double a, double b) { return std::fabs(a - b) / std::max(1.0, std::max(std::fabs(a), std::fabs(b))); }

struct Proj {
  std::vector<double> mean2d, conic, depth;
  std::vector<int> radius;
  int visible = 0;
};

template <class F>
Proj run_forward(const Scene& s, F project) {
  Proj p;
  p.mean2d.resize(2 * s.n);
  p.conic.resize(3 * s.n);
  p.depth.resize(s.n);
  p.radius.resize(s.n);
  p.visible = project(p);
  return p;
}

TEST(ProjectPacks, DoublePacksMatchTheScalarProjection) {
  for (int n : {1, 7, 8, 9, 203}) {
    const Scene s = pack_scene(std::max(n, 10), 11 + n);
    const int m = n;  // project the first m Gaussians
    const CameraT<double> cam = make_camera<double>(s.cam);
    auto scalar = run_forward(s, [&](Proj& p) {
      return project_forward<double>(cam, m, s.mean.data(), s.log_scale.data(), s.quat.data(), p.mean2d.data(),
                                     p.conic.data(), p.depth.data(), p.radius.data());
    });
    auto packs = run_forward(s, [&](Proj& p) {
      return project_forward_packs<double>(cam, m, s.mean.data(), s.log_scale.data(), s.quat.data(), p.mean2d.data(),
                                           p.conic.data(), p.depth.data(), p.radius.data());
    });
    ASSERT_EQ(scalar.visible, packs.visible) << "n=" << n;
    if (n == 203) {
      EXPECT_GT(scalar.visible, 100);
      EXPECT_LT(scalar.visible, n);  // some are culled
    }
    for (int i = 0; i < m; ++i) {
      ASSERT_EQ(scalar.radius[i], packs.radius[i]) << "Gaussian " << i;
      for (int k = 0; k < 2; ++k) EXPECT_LT(rel(scalar.mean2d[2 * i + k], packs.mean2d[2 * i + k]), 1e-12);
      for (int k = 0; k < 3; ++k) EXPECT_LT(rel(scalar.conic[3 * i + k], packs.conic[3 * i + k]), 1e-12);
      EXPECT_LT(rel(scalar.depth[i], packs.depth[i]), 1e-12);
    }
    // backward with random upstream gradients (and without the depth gradient)
    std::mt19937 rng(n);
    std::normal_distribution<double> N01(0, 1);
    std::vector<double> g2(2 * m), gc(3 * m), gd(m);
    for (double& v : g2) v = N01(rng);
    for (double& v : gc) v = 100 * N01(rng);
    for (double& v : gd) v = N01(rng);
    for (bool with_depth : {true, false}) {
      std::vector<double> a(10 * m, -1), b(10 * m, -2);
      auto back = [&](auto fn, std::vector<double>& o) {
        fn(cam, m, s.mean.data(), s.log_scale.data(), s.quat.data(), scalar.radius.data(), g2.data(), gc.data(),
           with_depth ? gd.data() : nullptr, o.data(), o.data() + 3 * m, o.data() + 6 * m);
      };
      back(project_backward<double>, a);
      back(project_backward_packs<double>, b);
      for (int j = 0; j < 10 * m; ++j) EXPECT_LT(rel(a[j], b[j]), 1e-10) << "entry " << j;
    }
  }
}

// The float packs' exp (simd::vexp, written for the rasterizer's x <= 0) over the log-scales a model can hold.
TEST(ProjectPacks, PackExpIsAccurateOnLogScales) {
  using P = simd::Pack<float>;
  double worst = 0;
  for (int i = 0; i < 4000; ++i) {
    P x;
    for (int l = 0; l < simd::kLanes; ++l) x[l] = -30.f + 45.f * float(i * simd::kLanes + l) / (4000 * simd::kLanes);
    const P e = lanes::Ops<P>::exp(x);
    for (int l = 0; l < simd::kLanes; ++l) worst = std::max(worst, std::fabs(e[l] / std::exp(double(x[l])) - 1));
  }
  EXPECT_LT(worst, 3e-7);  // 2.5 float ulps
}

TEST(ProjectPacks, FloatPacksMatchTheDoubleProjection) {
  const Scene s = pack_scene(403, 5);
  const int n = s.n;
  const CameraT<double> camd = make_camera<double>(s.cam);
  const CameraT<float> camf = make_camera<float>(s.cam);
  std::vector<float> mf(s.mean.begin(), s.mean.end()), lf(s.log_scale.begin(), s.log_scale.end()),
      qf(s.quat.begin(), s.quat.end());
  // the double reference on the float inputs
  const std::vector<double> md(mf.begin(), mf.end()), ld(lf.begin(), lf.end()), qd(qf.begin(), qf.end());
  Proj ref;
  ref.mean2d.resize(2 * n), ref.conic.resize(3 * n), ref.depth.resize(n), ref.radius.resize(n);
  ref.visible = project_forward<double>(camd, n, md.data(), ld.data(), qd.data(), ref.mean2d.data(), ref.conic.data(),
                                        ref.depth.data(), ref.radius.data());
  std::vector<float> m2(2 * n), co(3 * n), de(n);
  std::vector<int> rf(n);
  const int vis =
      project_forward<float>(camf, n, mf.data(), lf.data(), qf.data(), m2.data(), co.data(), de.data(), rf.data());
  EXPECT_NEAR(vis, ref.visible, 2);
  int radius_off = 0, both = 0;
  for (int i = 0; i < n; ++i) {
    if (rf[i] != ref.radius[i]) {
      ++radius_off;
      EXPECT_LE(std::abs(rf[i] - ref.radius[i]), 1) << "Gaussian " << i;  // a ceil on a rounding boundary
    }
    if (rf[i] == 0 || ref.radius[i] == 0) continue;
    ++both;
    for (int k = 0; k < 2; ++k) EXPECT_LT(rel(m2[2 * i + k], ref.mean2d[2 * i + k]), 1e-5);
    for (int k = 0; k < 3; ++k) {
      const double scale = std::fabs(ref.conic[3 * i]) + std::fabs(ref.conic[3 * i + 2]);
      EXPECT_LT(std::fabs(co[3 * i + k] - ref.conic[3 * i + k]), 1e-4 * scale) << "Gaussian " << i;
    }
    EXPECT_LT(rel(de[i], ref.depth[i]), 1e-6);
  }
  EXPECT_GT(both, 200);
  EXPECT_LE(radius_off, n / 50);
  // backward on the Gaussians both see
  std::mt19937 rng(9);
  std::normal_distribution<double> N01(0, 1);
  std::vector<int> rad(n);
  for (int i = 0; i < n; ++i) rad[i] = rf[i] > 0 && ref.radius[i] > 0 ? rf[i] : 0;
  std::vector<double> g2d(2 * n), gcd(3 * n), gdd(n), outd(10 * n);
  for (double& v : g2d) v = float(N01(rng));
  for (double& v : gcd) v = float(100 * N01(rng));
  for (double& v : gdd) v = float(N01(rng));
  const std::vector<float> g2f(g2d.begin(), g2d.end()), gcf(gcd.begin(), gcd.end()), gdf(gdd.begin(), gdd.end());
  std::vector<float> outf(10 * n);
  project_backward<double>(camd, n, md.data(), ld.data(), qd.data(), rad.data(), g2d.data(), gcd.data(), gdd.data(),
                           outd.data(), outd.data() + 3 * n, outd.data() + 6 * n);
  project_backward<float>(camf, n, mf.data(), lf.data(), qf.data(), rad.data(), g2f.data(), gcf.data(), gdf.data(),
                          outf.data(), outf.data() + 3 * n, outf.data() + 6 * n);
  for (int part = 0; part < 3; ++part) {  // dmean, dlog_scale, dquat: each Gaussian's vector against its norm
    const int off = part == 0 ? 0 : part == 1 ? 3 * n : 6 * n, w = part == 2 ? 4 : 3;
    for (int i = 0; i < n; ++i) {
      double norm = 0;
      for (int k = 0; k < w; ++k) norm += outd[off + w * i + k] * outd[off + w * i + k];
      norm = std::sqrt(norm);
      for (int k = 0; k < w; ++k) {
        if (rad[i] == 0) {
          EXPECT_EQ(outf[off + w * i + k], 0.f);
        } else {
          EXPECT_LT(std::fabs(outf[off + w * i + k] - outd[off + w * i + k]), 2e-4 * norm + 1e-9)
              << "part " << part << " Gaussian " << i;
        }
      }
    }
  }
}

}  // namespace
}  // namespace hgs::render::test
