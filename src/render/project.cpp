// Array drivers of the EWA projection (per-Gaussian math in project.h), parallel over Gaussians.
#include "render/project.h"

namespace hgs::render {

template <class T>
int project_forward(const CameraT<T>& cam, int n, const T* mean, const T* log_scale, const T* quat, T* mean2d, T* conic,
                    T* depth, int* radius) {
  int visible = 0;
#pragma omp parallel for schedule(static) reduction(+ : visible)
  for (int i = 0; i < n; ++i) {
    ProjectionTrace<T> tr;
    if (project_one(cam, mean + 3 * i, log_scale + 3 * i, quat + 4 * i, tr)) {
      mean2d[2 * i] = tr.mean2d[0];
      mean2d[2 * i + 1] = tr.mean2d[1];
      for (int k = 0; k < 3; ++k) conic[3 * i + k] = tr.conic[k];
      depth[i] = tr.tc[2];
      radius[i] = tr.radius;
      ++visible;
    } else {
      mean2d[2 * i] = mean2d[2 * i + 1] = 0;
      conic[3 * i] = conic[3 * i + 1] = conic[3 * i + 2] = 0;
      depth[i] = 0;
      radius[i] = 0;
    }
  }
  return visible;
}

template <class T>
void project_backward(const CameraT<T>& cam, int n, const T* mean, const T* log_scale, const T* quat, const int* radius,
                      const T* dmean2d, const T* dconic, const T* ddepth, T* dmean, T* dlog_scale, T* dquat) {
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

}  // namespace hgs::render
