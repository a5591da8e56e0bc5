// Test helpers for the render module: random scenes and an independent brute-force reference renderer
// (Eigen projection, per-pixel loop over every Gaussian sorted by depth, no tiles, double precision).
// The reference also returns a "decision signature" (every discrete choice the forward makes: culling, x/y
// clamping, SH clamping, tile coverage, alpha < 1/255 skips, the 0.99 clamp, the T cut-off) so finite-difference
// checks can verify that +-h perturbations stay on the same side of every discontinuity.
#pragma once
#include <Eigen/Dense>
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <numeric>
#include <random>
#include <vector>

#include "render/renderer.h"

namespace hgs::render::test {

struct Scene {
  Camera cam;
  int n = 0, sh_degree = 3, sh_stride = 16, num_extra = 0;
  std::vector<double> mean, log_scale, quat, opacity_logit, sh, colors, extra;
  bool use_colors = false;
  RenderSettings settings;
  std::vector<float> pixel_weights;  // [J, H, W] optional weight maps (planar, as the renderer reads them)
  int num_weights = 0;

  // Random soft weight maps; the settings point into this scene (keep it alive and unmoved while rendering).
  void add_pixel_weights(int J, uint32_t seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> U(0, 1);
    num_weights = J;
    pixel_weights.resize(size_t(cam.width) * cam.height * J);
    for (float& v : pixel_weights) v = U(rng) < 0.3f ? 0.f : U(rng);
    settings.pixel_weights = pixel_weights.data();
    settings.num_pixel_weights = J;
  }

  // Hard masks, as the hybrid method passes them: pixel p has weight 1 in map label(p) - 1 and 0 in the others
  // (label 0 = none), the labels being vertical stripes, so most 8-pixel batches see one map and some two.
  void add_label_weights(int J, int stripe) {
    num_weights = J;
    pixel_weights.assign(size_t(cam.width) * cam.height * J, 0.f);
    for (int y = 0; y < cam.height; ++y)
      for (int x = 0; x < cam.width; ++x) {
        const int label = (x / stripe + y / 16) % (J + 1);
        if (label > 0) pixel_weights[(size_t(label - 1) * cam.height + y) * cam.width + x] = 1.f;
      }
    settings.pixel_weights = pixel_weights.data();
    settings.num_pixel_weights = J;
  }

  template <class T>
  GaussianInputsT<T> inputs(std::vector<std::vector<T>>& store) const {
    store.clear();
    auto conv = [&](const std::vector<double>& v) -> const T* {
      store.emplace_back(v.begin(), v.end());
      return store.back().empty() ? nullptr : store.back().data();
    };
    store.reserve(8);
    GaussianInputsT<T> g;
    g.n = n;
    g.mean = conv(mean);
    g.log_scale = conv(log_scale);
    g.quat = conv(quat);
    g.opacity_logit = conv(opacity_logit);
    g.sh = use_colors ? nullptr : conv(sh);
    g.sh_stride = sh_stride;
    g.sh_degree = sh_degree;
    g.colors = use_colors ? conv(colors) : nullptr;
    g.extra = num_extra > 0 ? conv(extra) : nullptr;
    g.num_extra = num_extra;
    return g;
  }
};

// A small camera looking down +z from a slightly rotated pose.
inline Camera test_camera(int w, int h, std::mt19937& rng) {
  Camera c;
  c.width = w;
  c.height = h;
  c.fx = 0.9f * w;
  c.fy = 0.95f * w;
  c.cx = 0.5f * w + 0.7f;
  c.cy = 0.5f * h - 0.4f;
  std::uniform_real_distribution<double> u(-0.15, 0.15);
  Eigen::Matrix3d R =
      (Eigen::AngleAxisd(u(rng), Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(u(rng), Eigen::Vector3d::UnitY()) *
       Eigen::AngleAxisd(u(rng), Eigen::Vector3d::UnitZ()))
          .toRotationMatrix();
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) c.R[3 * i + j] = float(R(i, j));
  c.t[0] = float(u(rng));
  c.t[1] = float(u(rng));
  c.t[2] = float(u(rng));
  c.near_plane = 0.2f;
  return c;
}

// Random scene in camera space, mapped to world space. Mix: ordinary Gaussians in the view frustum, some near
// the image border / tile borders, some outside the 1.3x FOV clamp but wide enough to reach the image, some just
// past the near plane, and some behind the camera (culled).
inline Scene random_scene(int n, int w, int h, uint32_t seed, double max_opacity = 0.9, int num_extra = 0) {
  std::mt19937 rng(seed);
  Scene s;
  s.cam = test_camera(w, h, rng);
  s.n = n;
  s.num_extra = num_extra;
  std::uniform_real_distribution<double> U(0, 1);
  std::normal_distribution<double> N01(0, 1);
  Eigen::Matrix3d R;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) R(i, j) = s.cam.R[3 * i + j];
  const Eigen::Vector3d t(s.cam.t[0], s.cam.t[1], s.cam.t[2]);
  const double tanx = 0.5 * w / s.cam.fx, tany = 0.5 * h / s.cam.fy;
  for (int i = 0; i < n; ++i) {
    const int kind = i % 10;
    double z = 2 + 4 * U(rng);
    double ax = (2 * U(rng) - 1) * tanx, ay = (2 * U(rng) - 1) * tany;
    double ls = std::log(0.02 + 0.12 * U(rng)) + std::log(z / 3);
    if (kind == 7) {  // outside the clamp range, large
      ax = (U(rng) < 0.5 ? -1 : 1) * tanx * (1.45 + 0.3 * U(rng));
      ls = std::log(0.5 + 0.3 * U(rng));
    } else if (kind == 8) {  // close to the near plane (0.2) but past it
      z = 0.45 + 0.3 * U(rng);
      ls = std::log(0.01 + 0.015 * U(rng));
    } else if (kind == 9 && i % 20 == 9) {  // behind the camera
      z = -0.5 - U(rng);
    }
    const Eigen::Vector3d pc(ax * z, ay * z, z);
    const Eigen::Vector3d pw = R.transpose() * (pc - t);
    for (int k = 0; k < 3; ++k) s.mean.push_back(pw[k]);
    for (int k = 0; k < 3; ++k) s.log_scale.push_back(ls + 0.5 * N01(rng));
    double q[4], qq = 0;
    for (double& v : q) {
      v = N01(rng);
      qq += v * v;
    }
    const double qs = (0.5 + U(rng)) / std::sqrt(qq);  // not unit: the normalisation is part of the model
    for (double v : q) s.quat.push_back(v * qs);
    const double o = 0.05 + (max_opacity - 0.05) * U(rng);
    s.opacity_logit.push_back(std::log(o / (1 - o)));
    for (int k = 0; k < s.sh_stride; ++k)
      for (int c = 0; c < 3; ++c) s.sh.push_back(k == 0 ? 1.2 * N01(rng) : 0.25 * N01(rng));
    for (int c = 0; c < 3; ++c) s.colors.push_back(U(rng));
    for (int c = 0; c < num_extra; ++c) s.extra.push_back(N01(rng));
  }
  s.settings.background[0] = 0.2f;
  s.settings.background[1] = 0.5f;
  s.settings.background[2] = 0.9f;
  return s;
}

// ---------------------------------------------------------------------------------------------------------
// Reference renderer.

struct RefProjected {
  bool visible = false;
  double u = 0, v = 0, depth = 0, conic[3] = {0, 0, 0}, opacity = 0, color[3] = {0, 0, 0};
  int radius = 0;
  int tx0 = 1, tx1 = 0, ty0 = 1, ty1 = 0;  // 3-sigma tile rect
  bool clampx = false, clampy = false;
  int sh_clamped = 0;  // bit per channel
};

struct RefImage {
  std::vector<double> rgb, alpha, depth, extra, weight_sums;
  std::vector<int> signature;
};

inline double ref_sh(int deg, const double* sh, const Eigen::Vector3d& d, int c) {
  const double x = d[0], y = d[1], z = d[2];
  double b[16];
  b[0] = 0.28209479177387814;
  b[1] = -0.4886025119029199 * y;
  b[2] = 0.4886025119029199 * z;
  b[3] = -0.4886025119029199 * x;
  b[4] = 1.0925484305920792 * x * y;
  b[5] = -1.0925484305920792 * y * z;
  b[6] = 0.31539156525252005 * (2 * z * z - x * x - y * y);
  b[7] = -1.0925484305920792 * x * z;
  b[8] = 0.5462742152960396 * (x * x - y * y);
  b[9] = -0.5900435899266435 * y * (3 * x * x - y * y);
  b[10] = 2.890611442640554 * x * y * z;
  b[11] = -0.4570457994644658 * y * (4 * z * z - x * x - y * y);
  b[12] = 0.3731763325901154 * z * (2 * z * z - 3 * x * x - 3 * y * y);
  b[13] = -0.4570457994644658 * x * (4 * z * z - x * x - y * y);
  b[14] = 1.445305721320277 * z * (x * x - y * y);
  b[15] = -0.5900435899266435 * x * (x * x - 3 * y * y);
  double v = 0;
  for (int k = 0; k < (deg + 1) * (deg + 1); ++k) v += b[k] * sh[3 * k + c];
  return v + 0.5;
}

inline std::vector<RefProjected> ref_project(const Scene& s) {
  std::vector<RefProjected> out(s.n);
  Eigen::Matrix3d Wm;
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) Wm(i, j) = s.cam.R[3 * i + j];
  const Eigen::Vector3d tc(s.cam.t[0], s.cam.t[1], s.cam.t[2]);
  const Eigen::Vector3d campos = -Wm.transpose() * tc;
  const double fx = s.cam.fx, fy = s.cam.fy;
  const double limx = 1.3 * 0.5 * s.cam.width / fx, limy = 1.3 * 0.5 * s.cam.height / fy;
  for (int i = 0; i < s.n; ++i) {
    RefProjected& p = out[i];
    const Eigen::Vector3d m(s.mean[3 * i], s.mean[3 * i + 1], s.mean[3 * i + 2]);
    const Eigen::Vector3d c = Wm * m + tc;
    if (c.z() < double(s.cam.near_plane)) continue;
    Eigen::Quaterniond q(s.quat[4 * i], s.quat[4 * i + 1], s.quat[4 * i + 2], s.quat[4 * i + 3]);
    q.normalize();
    const Eigen::Matrix3d Rq = q.toRotationMatrix();
    const Eigen::Vector3d sc(std::exp(s.log_scale[3 * i]), std::exp(s.log_scale[3 * i + 1]),
                             std::exp(s.log_scale[3 * i + 2]));
    const Eigen::Matrix3d Sigma = Rq * sc.cwiseAbs2().asDiagonal() * Rq.transpose();
    const double xz = c.x() / c.z(), yz = c.y() / c.z();
    p.clampx = std::abs(xz) > limx;
    p.clampy = std::abs(yz) > limy;
    const double cxz = std::clamp(xz, -limx, limx) * c.z(), cyz = std::clamp(yz, -limy, limy) * c.z();
    Eigen::Matrix<double, 2, 3> J;
    J << fx / c.z(), 0, -fx * cxz / (c.z() * c.z()), 0, fy / c.z(), -fy * cyz / (c.z() * c.z());
    Eigen::Matrix2d cov = J * Wm * Sigma * Wm.transpose() * J.transpose();
    cov(0, 0) += 0.3;
    cov(1, 1) += 0.3;
    if (cov.determinant() <= 0) continue;
    const Eigen::Matrix2d K = cov.inverse();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> es(cov);
    const int r = int(std::ceil(3 * std::sqrt(es.eigenvalues().maxCoeff())));
    const double u = fx * c.x() / c.z() + s.cam.cx, v = fy * c.y() / c.z() + s.cam.cy;
    const int px0 = std::max(0, int(std::ceil(u - r - 0.5))),
              px1 = std::min(s.cam.width - 1, int(std::floor(u + r - 0.5)));
    const int py0 = std::max(0, int(std::ceil(v - r - 0.5))),
              py1 = std::min(s.cam.height - 1, int(std::floor(v + r - 0.5)));
    if (px0 > px1 || py0 > py1) continue;
    p.visible = true;
    p.u = u;
    p.v = v;
    p.depth = c.z();
    p.conic[0] = K(0, 0);
    p.conic[1] = K(0, 1);
    p.conic[2] = K(1, 1);
    p.radius = r;
    p.tx0 = px0 / 16, p.tx1 = px1 / 16, p.ty0 = py0 / 16, p.ty1 = py1 / 16;
    p.opacity = 1 / (1 + std::exp(-s.opacity_logit[i]));
    const Eigen::Vector3d dir = (m - campos).normalized();
    for (int ch = 0; ch < 3; ++ch) {
      double col =
          s.use_colors ? s.colors[3 * i + ch] : ref_sh(s.sh_degree, &s.sh[size_t(i) * s.sh_stride * 3], dir, ch);
      if (col < 0) {
        p.sh_clamped |= 1 << ch;
        col = 0;
      }
      p.color[ch] = col;
    }
  }
  return out;
}

// Per-pixel compositing over every visible Gaussian in (depth, index) order, honouring the 3DGS tile coverage
// (a Gaussian only reaches pixels of tiles its 3-sigma square touches).
inline RefImage ref_composite(const Scene& s, const std::vector<RefProjected>& P, bool want_depth = true) {
  const int W = s.cam.width, H = s.cam.height, C = s.num_extra;
  RefImage img;
  img.rgb.assign(size_t(W) * H * 3, 0);
  img.alpha.assign(size_t(W) * H, 0);
  img.depth.assign(want_depth ? size_t(W) * H : 0, 0);
  img.extra.assign(size_t(W) * H * C, 0);
  const int J = s.num_weights;
  img.weight_sums.assign(size_t(s.n) * J, 0);
  std::vector<int> order;
  for (int i = 0; i < s.n; ++i)
    if (P[i].visible) order.push_back(i);
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return P[a].depth < P[b].depth; });
  for (int i = 0; i < s.n; ++i) {
    img.signature.push_back(P[i].visible);
    img.signature.push_back(P[i].clampx + 2 * P[i].clampy + 4 * P[i].sh_clamped);
    img.signature.push_back(P[i].tx0 + 100 * P[i].tx1 + 10000 * P[i].ty0 + 1000000 * P[i].ty1);
  }
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const size_t p = size_t(y) * W + x;
      double T = 1, acc[3] = {0, 0, 0}, dep = 0;
      std::vector<double> ex(C, 0);
      bool done = false;
      for (int i : order) {
        const RefProjected& g = P[i];
        int code = 0;
        if (done) code = 5;
        else if (x / 16 < g.tx0 || x / 16 > g.tx1 || y / 16 < g.ty0 || y / 16 > g.ty1) code = 1;
        else {
          const double dx = g.u - (x + 0.5), dy = g.v - (y + 0.5);
          const double power = -0.5 * (g.conic[0] * dx * dx + g.conic[2] * dy * dy) - g.conic[1] * dx * dy;
          const double araw = g.opacity * std::exp(power);
          const double a = std::min(0.99, araw);
          if (a < 1.0 / 255.0) code = 2;
          else if (T * (1 - a) < 1e-4) {
            done = true;
            code = 4;
          } else {
            code = araw > 0.99 ? 6 : 3;
            const double w = a * T;
            for (int c = 0; c < 3; ++c) acc[c] += w * g.color[c];
            dep += w * g.depth;
            for (int c = 0; c < C; ++c) ex[c] += w * s.extra[size_t(i) * C + c];
            for (int j = 0; j < J; ++j)
              img.weight_sums[size_t(i) * J + j] += w * s.pixel_weights[size_t(j) * s.cam.width * s.cam.height + p];
            T *= 1 - a;
          }
        }
        img.signature.push_back(code);
      }
      for (int c = 0; c < 3; ++c) img.rgb[3 * p + c] = acc[c] + T * s.settings.background[c];
      img.alpha[p] = 1 - T;
      if (want_depth) img.depth[p] = dep;
      for (int c = 0; c < C; ++c) img.extra[p * C + c] = ex[c];
    }
  return img;
}

inline RefImage ref_render(const Scene& s, bool want_depth = true) {
  return ref_composite(s, ref_project(s), want_depth);
}

}  // namespace hgs::render::test
