// Array drivers of the spherical-harmonics colour (per-Gaussian math in sh.h), parallel over Gaussians.
#include "render/sh.h"

namespace hgs::render {

template <class T>
void sh_forward(int n, int degree, int stride, const T* sh, const T* mean, const T* campos, const int* active,
                T* colors) {
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    if (active && !active[i]) {
      colors[3 * i] = colors[3 * i + 1] = colors[3 * i + 2] = 0;
      continue;
    }
    const T dir[3] = {mean[3 * i] - campos[0], mean[3 * i + 1] - campos[1], mean[3 * i + 2] - campos[2]};
    sh_eval_one(degree, sh + size_t(i) * stride * 3, dir, colors + 3 * i);
  }
}

template <class T>
void sh_backward(int n, int degree, int stride, const T* sh, const T* mean, const T* campos, const int* active,
                 const T* dcolors, T* dsh, T* dmean) {
  const int K = sh_num_coeffs(degree);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    T* d = dsh + size_t(i) * stride * 3;
    for (int k = (active && !active[i]) ? 0 : K; k < stride; ++k) d[3 * k] = d[3 * k + 1] = d[3 * k + 2] = 0;
    if (active && !active[i]) continue;
    const T dir[3] = {mean[3 * i] - campos[0], mean[3 * i + 1] - campos[1], mean[3 * i + 2] - campos[2]};
    T ddir[3] = {0, 0, 0};
    sh_backward_one(degree, sh + size_t(i) * stride * 3, dir, dcolors + 3 * i, d, ddir);
    if (dmean)
      for (int j = 0; j < 3; ++j) dmean[3 * i + j] += ddir[j];
  }
}

template void sh_forward<float>(int, int, int, const float*, const float*, const float*, const int*, float*);
template void sh_forward<double>(int, int, int, const double*, const double*, const double*, const int*, double*);
template void sh_backward<float>(int, int, int, const float*, const float*, const float*, const int*, const float*,
                                 float*, float*);
template void sh_backward<double>(int, int, int, const double*, const double*, const double*, const int*,
                                  const double*, double*, double*);

}  // namespace hgs::render
