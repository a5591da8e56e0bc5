// Array drivers of the EWA projection (per-Gaussian math in project.h), parallel over Gaussians. float runs 8
// Gaussians per vector (project_pack.h: each pack's inputs gathered into lanes, the last pack padded with an
// identity Gaussian whose lanes are never written back); double (the finite-difference tests' renderer) runs
// one Gaussian at a time. Every Gaussian's result depends only on its own inputs, not on the thread count.
#include "render/project.h"

#include <algorithm>
#include <type_traits>

#include "core/parallel.h"
#include "render/project_pack.h"

namespace hgs::render {
namespace {

template <class T>
using PackOf = simd::Pack<T>;
constexpr int kL = simd::kLanes;

// Lanes of Gaussians [i0, i0 + cnt): out[k][l] = a[stride * (i0 + l) + k]; lanes >= cnt get pad[k].
template <class T, int K>
inline void gather(const T* a, int stride, int i0, int cnt, const T (&pad)[K], PackOf<T> (&out)[K]) {
  for (int k = 0; k < K; ++k) out[k] = lanes::splat<PackOf<T>>(pad[k]);
  for (int l = 0; l < cnt; ++l)
    for (int k = 0; k < K; ++k) out[k][l] = a[size_t(stride) * (i0 + l) + k];
}

// Gaussian i's outputs of project_forward: its projection where visible, zeros and radius 0 where culled.
template <class T>
inline void store_projected(size_t i, bool visible, T u, T v, const T (&k)[3], T z, int rad, T* mean2d, T* conic,
                            T* depth, int* radius) {
  mean2d[2 * i] = visible ? u : T(0);
  mean2d[2 * i + 1] = visible ? v : T(0);
  for (int c = 0; c < 3; ++c) conic[3 * i + c] = visible ? k[c] : T(0);
  depth[i] = visible ? z : T(0);
  radius[i] = visible ? rad : 0;
}

}  // namespace

template <class T>
int project_forward_packs(const CameraT<T>& cam, int n, const T* mean, const T* log_scale, const T* quat, T* mean2d,
                          T* conic, T* depth, int* radius) {
  using P = PackOf<T>;
  const int packs = (n + kL - 1) / kL;
  int visible = 0;
#pragma omp parallel for schedule(static) reduction(+ : visible)
  for (int pk = 0; pk < packs; ++pk) {
    const int i0 = pk * kL, cnt = std::min(kL, n - i0);
    P m[3], ls[3], q[4];
    gather<T, 3>(mean, 3, i0, cnt, {0, 0, 0}, m);
    gather<T, 3>(log_scale, 3, i0, cnt, {0, 0, 0}, ls);
    gather<T, 4>(quat, 4, i0, cnt, {1, 0, 0, 0}, q);
    ProjectionTrace<P> tr;
    const auto vis = project_lanes<P>(cam, m, ls, q, tr);
    for (int l = 0; l < cnt; ++l) {
      const T k[3] = {tr.conic[0][l], tr.conic[1][l], tr.conic[2][l]};
      store_projected(size_t(i0 + l), vis[l] != 0, tr.mean2d[0][l], tr.mean2d[1][l], k, tr.tc[2][l], int(tr.rad[l]),
                      mean2d, conic, depth, radius);
      visible += vis[l] != 0;
    }
  }
  return visible;
}

template <class T>
void project_backward_packs(const CameraT<T>& cam, int n, const T* mean, const T* log_scale, const T* quat,
                            const int* radius, const T* dmean2d, const T* dconic, const T* ddepth, T* dmean,
                            T* dlog_scale, T* dquat) {
  using P = PackOf<T>;
  const int packs = (n + kL - 1) / kL;
  // On demand (demand_chunk): only packs with a visible Gaussian do the work, and those cluster by index once
  // densification has appended its clones (a static split left threads idle).
#pragma omp parallel for schedule(dynamic, demand_chunk(packs, 8))
  for (int pk = 0; pk < packs; ++pk) {
    const int i0 = pk * kL, cnt = std::min(kL, n - i0);
    bool any = false;
    for (int l = 0; l < cnt; ++l) any |= radius[i0 + l] > 0;
    P dm[3] = {}, dl[3] = {}, dq[4] = {};  // stay zero for a pack without a visible Gaussian
    if (any) {
      P m[3], ls[3], q[4], g2[2], gc[3], gd[1];
      gather<T, 3>(mean, 3, i0, cnt, {0, 0, 0}, m);
      gather<T, 3>(log_scale, 3, i0, cnt, {0, 0, 0}, ls);
      gather<T, 4>(quat, 4, i0, cnt, {1, 0, 0, 0}, q);
      gather<T, 2>(dmean2d, 2, i0, cnt, {0, 0}, g2);
      gather<T, 3>(dconic, 3, i0, cnt, {0, 0, 0}, gc);
      if (ddepth) gather<T, 1>(ddepth, 1, i0, cnt, {0}, gd);
      else gd[0] = P{};
      ProjectionTrace<P> tr;
      project_lanes<P>(cam, m, ls, q, tr);
      project_lanes_backward<P>(cam, tr, g2, gc, gd[0], dm, dl, dq);
    }
    for (int l = 0; l < cnt; ++l) {
      const size_t i = size_t(i0 + l);
      const bool vis = radius[i] > 0;
      for (int k = 0; k < 3; ++k) {
        dmean[3 * i + k] = vis ? dm[k][l] : T(0);
        dlog_scale[3 * i + k] = vis ? dl[k][l] : T(0);
      }
      for (int k = 0; k < 4; ++k) dquat[4 * i + k] = vis ? dq[k][l] : T(0);
    }
  }
}

template <class T>
int project_forward(const CameraT<T>& cam, int n, const T* mean, const T* log_scale, const T* quat, T* mean2d, T* conic,
                    T* depth, int* radius) {
  if constexpr (std::is_same_v<T, float>)
    return project_forward_packs(cam, n, mean, log_scale, quat, mean2d, conic, depth, radius);
  int visible = 0;
#pragma omp parallel for schedule(static) reduction(+ : visible)
  for (int i = 0; i < n; ++i) {
    ProjectionTrace<T> tr;
    const bool vis = project_one(cam, mean + 3 * i, log_scale + 3 * i, quat + 4 * i, tr);
    store_projected(size_t(i), vis, tr.mean2d[0], tr.mean2d[1], tr.conic, tr.tc[2], tr.radius, mean2d, conic, depth,
                    radius);
    visible += vis;
  }
  return visible;
}

template <class T>
void project_backward(const CameraT<T>& cam, int n, const T* mean, const T* log_scale, const T* quat, const int* radius,
                      const T* dmean2d, const T* dconic, const T* ddepth, T* dmean, T* dlog_scale, T* dquat) {
  if constexpr (std::is_same_v<T, float>)
    return project_backward_packs(cam, n, mean, log_scale, quat, radius, dmean2d, dconic, ddepth, dmean, dlog_scale,
                                  dquat);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    if (radius[i] <= 0) {
      for (int k = 0; k < 3; ++k) dmean[3 * i + k] = dlog_scale[3 * i + k] = 0;
      for (int k = 0; k < 4; ++k) dquat[4 * i + k] = 0;
      continue;
    }
    ProjectionTrace<T> tr;
    project_one(cam, mean + 3 * i, log_scale + 3 * i, quat + 4 * i, tr);
    project_one_backward(cam, tr, dmean2d + 2 * i, dconic + 3 * i, ddepth ? ddepth[i] : T(0), dmean + 3 * i,
                         dlog_scale + 3 * i, dquat + 4 * i);
  }
}

template int project_forward<float>(const CameraT<float>&, int, const float*, const float*, const float*, float*,
                                    float*, float*, int*);
template int project_forward<double>(const CameraT<double>&, int, const double*, const double*, const double*, double*,
                                     double*, double*, int*);
template void project_backward<float>(const CameraT<float>&, int, const float*, const float*, const float*, const int*,
                                      const float*, const float*, const float*, float*, float*, float*);
template void project_backward<double>(const CameraT<double>&, int, const double*, const double*, const double*,
                                       const int*, const double*, const double*, const double*, double*, double*,
                                       double*);
template int project_forward_packs<double>(const CameraT<double>&, int, const double*, const double*, const double*,
                                           double*, double*, double*, int*);
template void project_backward_packs<double>(const CameraT<double>&, int, const double*, const double*, const double*,
                                             const int*, const double*, const double*, const double*, double*, double*,
                                             double*);

}  // namespace hgs::render
