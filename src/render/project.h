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
// The math is templated on the scalar so tests run it in double; the production path is T = float.
#pragma once
#include <algorithm>
#include <cmath>

#include "render/renderer.h"

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

// Rotation matrix (row-major) of a unit quaternion (w, x, y, z).
template <class T>
inline void quat_to_rot(const T* q, T* Rq) {
  T w = q[0], x = q[1], y = q[2], z = q[3];
  Rq[0] = 1 - 2 * (y * y + z * z);
  Rq[1] = 2 * (x * y - w * z);
  Rq[2] = 2 * (x * z + w * y);
  Rq[3] = 2 * (x * y + w * z);
  Rq[4] = 1 - 2 * (x * x + z * z);
  Rq[5] = 2 * (y * z - w * x);
  Rq[6] = 2 * (x * z - w * y);
  Rq[7] = 2 * (y * z + w * x);
  Rq[8] = 1 - 2 * (x * x + y * y);
}

// Everything the projection of one Gaussian computes; backward recomputes it.
template <class T>
struct ProjectionTrace {
  T tc[3];        // camera-space centre
  T clx, cly;     // clamped t_x/t_z, t_y/t_z
  bool inx, iny;  // not clamped
  T TW[6];        // J W, [2, 3]
  T qn[4], qnorm;
  T Rq[9], s[3], M[9];  // M = Rq diag(s)
  T A[6];               // TW M, [2, 3]
  T cov[3];             // 2D covariance incl. low-pass (c00, c01, c11)
  T conic[3];
  T mean2d[2];
  int radius;
};

// Forward for one Gaussian. Returns false (radius 0) when culled.
template <class T>
inline bool project_one(const CameraT<T>& cam, const T* mean, const T* log_scale, const T* quat,
                        ProjectionTrace<T>& tr) {
  tr.radius = 0;
  const T* W = cam.R;
  for (int r = 0; r < 3; ++r)
    tr.tc[r] = W[3 * r] * mean[0] + W[3 * r + 1] * mean[1] + W[3 * r + 2] * mean[2] + cam.t[r];
  const T tx = tr.tc[0], ty = tr.tc[1], tz = tr.tc[2];
  if (!(tz >= cam.near_plane)) return false;
  const T iz = T(1) / tz;
  tr.mean2d[0] = cam.fx * tx * iz + cam.cx;
  tr.mean2d[1] = cam.fy * ty * iz + cam.cy;
  const T txtz = tx * iz, tytz = ty * iz;
  tr.inx = txtz >= -cam.limx && txtz <= cam.limx;
  tr.iny = tytz >= -cam.limy && tytz <= cam.limy;
  tr.clx = std::min(cam.limx, std::max(-cam.limx, txtz));
  tr.cly = std::min(cam.limy, std::max(-cam.limy, tytz));
  const T J00 = cam.fx * iz, J02 = -cam.fx * tr.clx * iz;
  const T J11 = cam.fy * iz, J12 = -cam.fy * tr.cly * iz;
  for (int j = 0; j < 3; ++j) {
    tr.TW[j] = J00 * W[j] + J02 * W[6 + j];
    tr.TW[3 + j] = J11 * W[3 + j] + J12 * W[6 + j];
  }
  T qq = quat[0] * quat[0] + quat[1] * quat[1] + quat[2] * quat[2] + quat[3] * quat[3];
  tr.qnorm = std::sqrt(qq);
  const T iq = tr.qnorm > T(0) ? T(1) / tr.qnorm : T(0);
  for (int i = 0; i < 4; ++i) tr.qn[i] = quat[i] * iq;
  if (!(tr.qnorm > T(0))) tr.qn[0] = 1;
  quat_to_rot(tr.qn, tr.Rq);
  for (int j = 0; j < 3; ++j) tr.s[j] = std::exp(log_scale[j]);
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) tr.M[3 * i + j] = tr.Rq[3 * i + j] * tr.s[j];
  for (int r = 0; r < 2; ++r)
    for (int j = 0; j < 3; ++j)
      tr.A[3 * r + j] = tr.TW[3 * r] * tr.M[j] + tr.TW[3 * r + 1] * tr.M[3 + j] + tr.TW[3 * r + 2] * tr.M[6 + j];
  tr.cov[0] = tr.A[0] * tr.A[0] + tr.A[1] * tr.A[1] + tr.A[2] * tr.A[2] + T(kLowPass);
  tr.cov[1] = tr.A[0] * tr.A[3] + tr.A[1] * tr.A[4] + tr.A[2] * tr.A[5];
  tr.cov[2] = tr.A[3] * tr.A[3] + tr.A[4] * tr.A[4] + tr.A[5] * tr.A[5] + T(kLowPass);
  const T det = tr.cov[0] * tr.cov[2] - tr.cov[1] * tr.cov[1];
  if (!(det > T(0))) return false;
  const T idet = T(1) / det;
  tr.conic[0] = tr.cov[2] * idet;
  tr.conic[1] = -tr.cov[1] * idet;
  tr.conic[2] = tr.cov[0] * idet;
  const T mid = T(0.5) * (tr.cov[0] + tr.cov[2]);
  const T lam = mid + std::sqrt(std::max(T(0), mid * mid - det));
  const T rad = std::ceil(T(3) * std::sqrt(lam));
  if (!(rad < T(1e7))) return false;
  // Pixel x has its centre at x + 0.5: the square covers pixels in [ceil(u - r - 0.5), floor(u + r - 0.5)].
  const T u = tr.mean2d[0], v = tr.mean2d[1];
  if (std::floor(u + rad - T(0.5)) < T(0) || std::ceil(u - rad - T(0.5)) > T(cam.width - 1) ||
      std::floor(v + rad - T(0.5)) < T(0) || std::ceil(v - rad - T(0.5)) > T(cam.height - 1))
    return false;
  tr.radius = int(rad);
  return true;
}

// Backward for one visible Gaussian: upstream dL/d(mean2d) [2], dL/d(conic) [3] (b counted once, as stored),
// dL/d(depth). Writes dL/d(mean) [3], dL/d(log_scale) [3], dL/d(quat) [4] (overwrites).
template <class T>
inline void project_one_backward(const CameraT<T>& cam, const ProjectionTrace<T>& tr, const T* dmean2d, const T* dconic,
                                 T ddepth, T* dmean, T* dlog_scale, T* dquat) {
  const T* W = cam.R;
  const T tx = tr.tc[0], tz = tr.tc[2];
  const T ty = tr.tc[1];
  const T iz = T(1) / tz, iz2 = iz * iz;
  // conic = cov^-1: dL/dcov = -K G K with G the symmetric gradient [[ga, gb/2], [gb/2, gc]].
  const T k0 = tr.conic[0], k1 = tr.conic[1], k2 = tr.conic[2];
  const T ga = dconic[0], gb = T(0.5) * dconic[1], gc = dconic[2];
  // P = G K
  const T p00 = ga * k0 + gb * k1, p01 = ga * k1 + gb * k2;
  const T p10 = gb * k0 + gc * k1, p11 = gb * k1 + gc * k2;
  // K P
  const T g00 = -(k0 * p00 + k1 * p10);
  const T g01 = -(k0 * p01 + k1 * p11);  // symmetric matrix entry
  const T g11 = -(k1 * p01 + k2 * p11);
  // cov = A A^T: dL/dA = 2 Gcov A with Gcov = [[g00, g01], [g01, g11]]
  T dA[6];
  for (int j = 0; j < 3; ++j) {
    dA[j] = T(2) * (g00 * tr.A[j] + g01 * tr.A[3 + j]);
    dA[3 + j] = T(2) * (g01 * tr.A[j] + g11 * tr.A[3 + j]);
  }
  // A = TW M
  T dTW[6], dM[9];
  for (int r = 0; r < 2; ++r)
    for (int i = 0; i < 3; ++i)
      dTW[3 * r + i] = dA[3 * r] * tr.M[3 * i] + dA[3 * r + 1] * tr.M[3 * i + 1] + dA[3 * r + 2] * tr.M[3 * i + 2];
  for (int i = 0; i < 3; ++i)
    for (int j = 0; j < 3; ++j) dM[3 * i + j] = tr.TW[i] * dA[j] + tr.TW[3 + i] * dA[3 + j];
  // TW rows: J00 W0 + J02 W2, J11 W1 + J12 W2
  const T dJ00 = dTW[0] * W[0] + dTW[1] * W[1] + dTW[2] * W[2];
  const T dJ02 = dTW[0] * W[6] + dTW[1] * W[7] + dTW[2] * W[8];
  const T dJ11 = dTW[3] * W[3] + dTW[4] * W[4] + dTW[5] * W[5];
  const T dJ12 = dTW[3] * W[6] + dTW[4] * W[7] + dTW[5] * W[8];
  // J00 = fx/tz; J02 = -fx clx/tz with clx = tx/tz unless clamped (then constant).
  T dtx = 0, dty = 0, dtz = 0;
  dtz += -cam.fx * iz2 * dJ00 - cam.fy * iz2 * dJ11;
  if (tr.inx) {
    dtx += -cam.fx * iz2 * dJ02;
    dtz += T(2) * cam.fx * tx * iz2 * iz * dJ02;
  } else {
    dtz += cam.fx * tr.clx * iz2 * dJ02;
  }
  if (tr.iny) {
    dty += -cam.fy * iz2 * dJ12;
    dtz += T(2) * cam.fy * ty * iz2 * iz * dJ12;
  } else {
    dtz += cam.fy * tr.cly * iz2 * dJ12;
  }
  // projected centre and depth
  dtx += cam.fx * iz * dmean2d[0];
  dty += cam.fy * iz * dmean2d[1];
  dtz += -cam.fx * tx * iz2 * dmean2d[0] - cam.fy * ty * iz2 * dmean2d[1] + ddepth;
  for (int j = 0; j < 3; ++j) dmean[j] = W[j] * dtx + W[3 + j] * dty + W[6 + j] * dtz;
  // M = Rq diag(s)
  T dR[9];
  for (int j = 0; j < 3; ++j) {
    T ds = 0;
    for (int i = 0; i < 3; ++i) {
      dR[3 * i + j] = dM[3 * i + j] * tr.s[j];
      ds += dM[3 * i + j] * tr.Rq[3 * i + j];
    }
    dlog_scale[j] = ds * tr.s[j];
  }
  const T w = tr.qn[0], x = tr.qn[1], y = tr.qn[2], z = tr.qn[3];
  T dq[4];
  dq[0] = 2 * (-z * dR[1] + y * dR[2] + z * dR[3] - x * dR[5] - y * dR[6] + x * dR[7]);
  dq[1] = 2 * (y * dR[1] + z * dR[2] + y * dR[3] - 2 * x * dR[4] - w * dR[5] + z * dR[6] + w * dR[7] - 2 * x * dR[8]);
  dq[2] = 2 * (-2 * y * dR[0] + x * dR[1] + w * dR[2] + x * dR[3] + z * dR[5] - w * dR[6] + z * dR[7] - 2 * y * dR[8]);
  dq[3] = 2 * (-2 * z * dR[0] - w * dR[1] + x * dR[2] + w * dR[3] - 2 * z * dR[4] + y * dR[5] + x * dR[6] + y * dR[7]);
  if (tr.qnorm > T(0)) {
    const T dot = dq[0] * w + dq[1] * x + dq[2] * y + dq[3] * z;
    for (int i = 0; i < 4; ++i) dquat[i] = (dq[i] - tr.qn[i] * dot) / tr.qnorm;
  } else {
    for (int i = 0; i < 4; ++i) dquat[i] = 0;
  }
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
