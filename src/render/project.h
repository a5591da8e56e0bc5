// EWA projection of 3D Gaussians (3DGS / gsplat conventions), forward and exact backward.
//
// For one Gaussian: t = R x + t_cam (camera space), depth = t_z, culled when depth < near_plane.
// Projected centre u = fx t_x / t_z + cx, v = fy t_y / t_z + cy (pixel units, COLMAP convention).
// Covariance Sigma = M M^T with M = R(q/|q|) diag(exp(log_scale)); 2D covariance cov = J W Sigma W^T J^T + 0.3 I
// where W is the camera rotation and J the perspective Jacobian at the centre, evaluated with t_x/t_z and t_y/t_z
// clamped to +-1.3 tan(half FOV) (so J has no dependence on t_x or t_y when clamped: the gradient through the
// clamped branch is zero for t_x/t_y and the exact one for t_z). conic = cov^-1 stored (a, b, c) for
// [[a, b], [b, c]]; radius = ceil(3 sqrt(max eigenvalue of cov)); culled when the 3-sigma square around the
// centre contains no pixel centre of the image. Backward recomputes the forward intermediates (no saved state).
// The math (project_lanes, project_lanes_backward) is written once for V = a scalar (one Gaussian: double for the
// tests and the double renderer) or an 8-lane pack (8 Gaussians per vector: the float renderer, project_pack.h),
// branch-free: culling is a mask over the lanes.
#pragma once
#include <algorithm>
#include <cmath>

#include "render/renderer.h"

// project_lanes on 64-byte double packs (project_pack.h, tests) changes the ABI of non-inlined helpers; silence
// GCC's note.
#pragma GCC diagnostic ignored "-Wpsabi"

namespace hgs::render {

// Camera in scalar T with the derived quantities the projection needs.
template <class T>
struct CameraT {
  int width = 0, height = 0;
  T fx = 0, fy = 0, cx = 0, cy = 0;
  T R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // world -> camera, row-major
  T t[3] = {0, 0, 0};
  T near_plane = T(0.01);
  T limx = 0, limy = 0;     // 1.3 * tan(half FOV) in x and y
  T campos[3] = {0, 0, 0};  // camera centre in world space (-R^T t)
};

template <class T>
CameraT<T> make_camera(const Camera& c) {
  CameraT<T> k;
  k.width = c.width;
  k.height = c.height;
  k.fx = c.fx;
  k.fy = c.fy;
  k.cx = c.cx;
  k.cy = c.cy;
  for (int i = 0; i < 9; ++i) k.R[i] = c.R[i];
  for (int i = 0; i < 3; ++i) k.t[i] = c.t[i];
  k.near_plane = c.near_plane;
  k.limx = T(1.3) * (T(0.5) * T(c.width) / k.fx);
  k.limy = T(1.3) * (T(0.5) * T(c.height) / k.fy);
  for (int i = 0; i < 3; ++i) k.campos[i] = -(k.R[0 + i] * k.t[0] + k.R[3 + i] * k.t[1] + k.R[6 + i] * k.t[2]);
  return k;
}

constexpr double kLowPass = 0.3;  // px^2 added to the 2D covariance diagonal

// Lane-generic arithmetic: the projection below is written once for V = float or double (one Gaussian; the
// finite-difference tests and the double renderer) and for V = an 8-lane pack of them (8 Gaussians per vector;
// the float renderer, render/project_pack.h specialises Ops for the packs). Culling is branch-free (a mask), so
// every lane computes the whole projection and the mask says which lanes are visible.
namespace lanes {
template <class V>
struct Ops {  // scalars; M is the type of a comparison
  using S = V;
  using M = bool;
  static V sqrt(V x) { return std::sqrt(x); }
  static V exp(V x) { return std::exp(x); }
  static V ceil(V x) { return std::ceil(x); }
  static V floor(V x) { return std::floor(x); }
};
template <class V>
inline V splat(typename Ops<V>::S s) {
  return V{} + s;
}
template <class V>
inline V vmax(V a, V b) {  // std::max's choice, lane-wise
  return a < b ? b : a;
}
template <class V>
inline V vmin(V a, V b) {  // std::min's choice, lane-wise
  return b < a ? b : a;
}
}  // namespace lanes

// Rotation matrix (row-major) of a unit quaternion (w, x, y, z).
template <class V>
inline void quat_to_rot(const V* q, V* Rq) {
  using S = typename lanes::Ops<V>::S;
  const V w = q[0], x = q[1], y = q[2], z = q[3];
  Rq[0] = S(1) - S(2) * (y * y + z * z);
  Rq[1] = S(2) * (x * y - w * z);
  Rq[2] = S(2) * (x * z + w * y);
  Rq[3] = S(2) * (x * y + w * z);
  Rq[4] = S(1) - S(2) * (x * x + z * z);
  Rq[5] = S(2) * (y * z - w * x);
  Rq[6] = S(2) * (x * z - w * y);
  Rq[7] = S(2) * (y * z + w * x);
  Rq[8] = S(1) - S(2) * (x * x + y * y);
}

// Everything the projection of one Gaussian (or one pack of them) computes; backward recomputes it.
template <class V>
struct ProjectionTrace {
  using Mask = typename lanes::Ops<V>::M;
  V tc[3];        // camera-space centre
  V clx, cly;     // clamped t_x/t_z, t_y/t_z
  Mask inx, iny;  // not clamped
  V TW[6];        // J W, [2, 3]
  V qn[4], qnorm;
  V Rq[9], s[3], M[9];  // M = Rq diag(s)
  V A[6];               // TW M, [2, 3]
  V cov[3];             // 2D covariance incl. low-pass (c00, c01, c11)
  V conic[3];
  V mean2d[2];
  V rad;       // ceil(3 sqrt(max eigenvalue)), as a float (meaningful where visible)
  int radius;  // int(rad) where visible, else 0 (set by project_one only)
};

// Forward of one Gaussian or one pack: fills tr and returns where the Gaussian is visible (not culled).
// mean [3], log_scale [3], quat [4] of V.
template <class V>
inline typename lanes::Ops<V>::M project_lanes(const CameraT<typename lanes::Ops<V>::S>& cam, const V* mean,
                                               const V* log_scale, const V* quat, ProjectionTrace<V>& tr) {
  using Op = lanes::Ops<V>;
  using S = typename Op::S;
  using lanes::splat;
  const S* W = cam.R;
  for (int r = 0; r < 3; ++r)
    tr.tc[r] = W[3 * r] * mean[0] + W[3 * r + 1] * mean[1] + W[3 * r + 2] * mean[2] + cam.t[r];
  const V tx = tr.tc[0], ty = tr.tc[1], tz = tr.tc[2];
  typename Op::M visible = tz >= cam.near_plane;
  const V iz = S(1) / tz;
  tr.mean2d[0] = cam.fx * tx * iz + cam.cx;
  tr.mean2d[1] = cam.fy * ty * iz + cam.cy;
  const V txtz = tx * iz, tytz = ty * iz;
  tr.inx = (txtz >= -cam.limx) & (txtz <= cam.limx);
  tr.iny = (tytz >= -cam.limy) & (tytz <= cam.limy);
  tr.clx = lanes::vmin(splat<V>(cam.limx), lanes::vmax(splat<V>(-cam.limx), txtz));
  tr.cly = lanes::vmin(splat<V>(cam.limy), lanes::vmax(splat<V>(-cam.limy), tytz));
  const V J00 = cam.fx * iz, J02 = -cam.fx * tr.clx * iz;
  const V J11 = cam.fy * iz, J12 = -cam.fy * tr.cly * iz;
  for (int j = 0; j < 3; ++j) {
    tr.TW[j] = J00 * W[j] + J02 * W[6 + j];
    tr.TW[3 + j] = J11 * W[3 + j] + J12 * W[6 + j];
  }
  const V qq = quat[0] * quat[0] + quat[1] * quat[1] + quat[2] * quat[2] + quat[3] * quat[3];
  tr.qnorm = Op::sqrt(qq);
  const typename Op::M qpos = tr.qnorm > S(0);
  const V iq = qpos ? S(1) / tr.qnorm : V{};
  for (int i = 0; i < 4; ++i) tr.qn[i] = quat[i] * iq;
  tr.qn[0] = qpos ? tr.qn[0] : splat<V>(S(1));
  quat_to_rot(tr.qn, tr.Rq);
  for (int j = 0; j < 3; ++j) tr.s[j] = Op::exp(log_scale[j]);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) tr.M[3 * i + j] = tr.Rq[3 * i + j] * tr.s[j];
  for (int r = 0; r < 2; ++r)
    for (int j = 0; j < 3; ++j)
      tr.A[3 * r + j] = tr.TW[3 * r] * tr.M[j] + tr.TW[3 * r + 1] * tr.M[3 + j] + tr.TW[3 * r + 2] * tr.M[6 + j];
  tr.cov[0] = tr.A[0] * tr.A[0] + tr.A[1] * tr.A[1] + tr.A[2] * tr.A[2] + S(kLowPass);
  tr.cov[1] = tr.A[0] * tr.A[3] + tr.A[1] * tr.A[4] + tr.A[2] * tr.A[5];
  tr.cov[2] = tr.A[3] * tr.A[3] + tr.A[4] * tr.A[4] + tr.A[5] * tr.A[5] + S(kLowPass);
  const V det = tr.cov[0] * tr.cov[2] - tr.cov[1] * tr.cov[1];
  visible = visible & (det > S(0));
  const V idet = S(1) / det;
  tr.conic[0] = tr.cov[2] * idet;
  tr.conic[1] = -tr.cov[1] * idet;
  tr.conic[2] = tr.cov[0] * idet;
  const V mid = S(0.5) * (tr.cov[0] + tr.cov[2]);
  const V lam = mid + Op::sqrt(lanes::vmax(V{}, mid * mid - det));
  tr.rad = Op::ceil(S(3) * Op::sqrt(lam));
  visible = visible & (tr.rad < S(1e7));
  // Pixel x has its centre at x + 0.5: the square covers pixels in [ceil(u - r - 0.5), floor(u + r - 0.5)], which
  // must hold a pixel of the image.
  const V u = tr.mean2d[0], v = tr.mean2d[1];
  visible = visible & (Op::floor(u + tr.rad - S(0.5)) >= S(0)) & (Op::ceil(u - tr.rad - S(0.5)) <= S(cam.width - 1)) &
            (Op::floor(v + tr.rad - S(0.5)) >= S(0)) & (Op::ceil(v - tr.rad - S(0.5)) <= S(cam.height - 1));
  return visible;
}

// Forward for one Gaussian. Returns false (radius 0) when culled.
template <class T>
inline bool project_one(const CameraT<T>& cam, const T* mean, const T* log_scale, const T* quat,
                        ProjectionTrace<T>& tr) {
  const bool visible = project_lanes<T>(cam, mean, log_scale, quat, tr);
  tr.radius = visible ? int(tr.rad) : 0;
  return visible;
}

// Backward of one visible Gaussian or pack: upstream dL/d(mean2d) [2], dL/d(conic) [3] (b counted once, as
// stored), dL/d(depth). Writes dL/d(mean) [3], dL/d(log_scale) [3], dL/d(quat) [4] (overwrites).
template <class V>
inline void project_lanes_backward(const CameraT<typename lanes::Ops<V>::S>& cam, const ProjectionTrace<V>& tr,
                                   const V* dmean2d, const V* dconic, V ddepth, V* dmean, V* dlog_scale, V* dquat) {
  using S = typename lanes::Ops<V>::S;
  const S* W = cam.R;
  const V tx = tr.tc[0], tz = tr.tc[2];
  const V ty = tr.tc[1];
  const V iz = S(1) / tz, iz2 = iz * iz;
  // conic = cov^-1: dL/dcov = -K G K with G the symmetric gradient [[ga, gb/2], [gb/2, gc]].
  const V k0 = tr.conic[0], k1 = tr.conic[1], k2 = tr.conic[2];
  const V ga = dconic[0], gb = S(0.5) * dconic[1], gc = dconic[2];
  // P = G K
  const V p00 = ga * k0 + gb * k1, p01 = ga * k1 + gb * k2;
  const V p10 = gb * k0 + gc * k1, p11 = gb * k1 + gc * k2;
  // K P
  const V g00 = -(k0 * p00 + k1 * p10);
  const V g01 = -(k0 * p01 + k1 * p11);  // symmetric matrix entry
  const V g11 = -(k1 * p01 + k2 * p11);
  // cov = A A^T: dL/dA = 2 Gcov A with Gcov = [[g00, g01], [g01, g11]]
  V dA[6];
  for (int j = 0; j < 3; ++j) {
    dA[j] = S(2) * (g00 * tr.A[j] + g01 * tr.A[3 + j]);
    dA[3 + j] = S(2) * (g01 * tr.A[j] + g11 * tr.A[3 + j]);
  }
  // A = TW M
  V dTW[6], dM[9];
  for (int r = 0; r < 2; ++r)
    for (int i = 0; i < 3; ++i)
      dTW[3 * r + i] = dA[3 * r] * tr.M[3 * i] + dA[3 * r + 1] * tr.M[3 * i + 1] + dA[3 * r + 2] * tr.M[3 * i + 2];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) dM[3 * i + j] = tr.TW[i] * dA[j] + tr.TW[3 + i] * dA[3 + j];
  // TW rows: J00 W0 + J02 W2, J11 W1 + J12 W2
  const V dJ00 = dTW[0] * W[0] + dTW[1] * W[1] + dTW[2] * W[2];
  const V dJ02 = dTW[0] * W[6] + dTW[1] * W[7] + dTW[2] * W[8];
  const V dJ11 = dTW[3] * W[3] + dTW[4] * W[4] + dTW[5] * W[5];
  const V dJ12 = dTW[3] * W[6] + dTW[4] * W[7] + dTW[5] * W[8];
  // J00 = fx/tz; J02 = -fx clx/tz with clx = tx/tz unless clamped (then constant).
  V dtx = V{}, dty = V{}, dtz = V{};
  dtz += -cam.fx * iz2 * dJ00 - cam.fy * iz2 * dJ11;
  dtx += tr.inx ? -cam.fx * iz2 * dJ02 : V{};
  dtz += tr.inx ? S(2) * cam.fx * tx * iz2 * iz * dJ02 : cam.fx * tr.clx * iz2 * dJ02;
  dty += tr.iny ? -cam.fy * iz2 * dJ12 : V{};
  dtz += tr.iny ? S(2) * cam.fy * ty * iz2 * iz * dJ12 : cam.fy * tr.cly * iz2 * dJ12;
  // projected centre and depth
  dtx += cam.fx * iz * dmean2d[0];
  dty += cam.fy * iz * dmean2d[1];
  dtz += -cam.fx * tx * iz2 * dmean2d[0] - cam.fy * ty * iz2 * dmean2d[1] + ddepth;
  for (int j = 0; j < 3; ++j) dmean[j] = W[j] * dtx + W[3 + j] * dty + W[6 + j] * dtz;
  // M = Rq diag(s)
  V dR[9];
  for (int j = 0; j < 3; ++j) {
    V ds = V{};
    for (int i = 0; i < 3; ++i) {
      dR[3 * i + j] = dM[3 * i + j] * tr.s[j];
      ds += dM[3 * i + j] * tr.Rq[3 * i + j];
    }
    dlog_scale[j] = ds * tr.s[j];
  }
  const V w = tr.qn[0], x = tr.qn[1], y = tr.qn[2], z = tr.qn[3];
  V dq[4];
  dq[0] = S(2) * (-z * dR[1] + y * dR[2] + z * dR[3] - x * dR[5] - y * dR[6] + x * dR[7]);
  dq[1] = S(2) *
          (y * dR[1] + z * dR[2] + y * dR[3] - S(2) * x * dR[4] - w * dR[5] + z * dR[6] + w * dR[7] - S(2) * x * dR[8]);
  dq[2] = S(2) * (-S(2) * y * dR[0] + x * dR[1] + w * dR[2] + x * dR[3] + z * dR[5] - w * dR[6] + z * dR[7] -
                  S(2) * y * dR[8]);
  dq[3] = S(2) * (-S(2) * z * dR[0] - w * dR[1] + x * dR[2] + w * dR[3] - S(2) * z * dR[4] + y * dR[5] + x * dR[6] +
                  y * dR[7]);
  const V dot = dq[0] * w + dq[1] * x + dq[2] * y + dq[3] * z;
  const typename lanes::Ops<V>::M qpos = tr.qnorm > S(0);
  for (int i = 0; i < 4; ++i) dquat[i] = qpos ? (dq[i] - tr.qn[i] * dot) / tr.qnorm : V{};
}

// Backward for one visible Gaussian (scalar; see project_lanes_backward).
template <class T>
inline void project_one_backward(const CameraT<T>& cam, const ProjectionTrace<T>& tr, const T* dmean2d, const T* dconic,
                                 T ddepth, T* dmean, T* dlog_scale, T* dquat) {
  project_lanes_backward<T>(cam, tr, dmean2d, dconic, ddepth, dmean, dlog_scale, dquat);
}

// Array forward over N Gaussians (parallel). Culled Gaussians get radius 0 (other outputs unspecified).
// Returns the number of visible Gaussians.
template <class T>
int project_forward(const CameraT<T>& cam, int n,
                    const T* mean,       // [N, 3]
                    const T* log_scale,  // [N, 3]
                    const T* quat,       // [N, 4]
                    T* mean2d,           // [N, 2] out
                    T* conic,            // [N, 3] out
                    T* depth,            // [N] out
                    int* radius);        // [N] out

// Array backward: overwrites dmean, dlog_scale, dquat (zero for culled Gaussians).
template <class T>
void project_backward(const CameraT<T>& cam, int n,
                      const T* mean,       // [N, 3]
                      const T* log_scale,  // [N, 3]
                      const T* quat,       // [N, 4]
                      const int* radius,   // [N] from project_forward
                      const T* dmean2d,    // [N, 2]
                      const T* dconic,     // [N, 3]
                      const T* ddepth,     // [N] (may be null)
                      T* dmean,            // [N, 3] out
                      T* dlog_scale,       // [N, 3] out
                      T* dquat);           // [N, 4] out

extern template int project_forward<float>(const CameraT<float>&, int, const float*, const float*, const float*, float*,
                                           float*, float*, int*);
extern template int project_forward<double>(const CameraT<double>&, int, const double*, const double*, const double*,
                                            double*, double*, double*, int*);
extern template void project_backward<float>(const CameraT<float>&, int, const float*, const float*, const float*,
                                             const int*, const float*, const float*, const float*, float*, float*,
                                             float*);
extern template void project_backward<double>(const CameraT<double>&, int, const double*, const double*, const double*,
                                              const int*, const double*, const double*, const double*, double*, double*,
                                              double*);

}  // namespace hgs::render
