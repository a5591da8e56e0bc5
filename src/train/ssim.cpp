// SSIM forward and exact backward with separable convolutions.
// Forward: the five local moments mu_x = w*x, mu_y = w*y, E[xx] = w*x^2, E[yy] = w*y^2, E[xy] = w*(xy) are
// 11-tap horizontal then vertical passes (zero padding). With A1 = 2 mu_x mu_y + C1, A2 = 2 s_xy + C2,
// B1 = mu_x^2 + mu_y^2 + C1, B2 = s_xx + s_yy + C2 (s_xx = E[xx] - mu_x^2, s_xy = E[xy] - mu_x mu_y) the map is
// A1 A2 / (B1 B2). Backward: with g = 1/(HWC), the map's partials in (mu_x, E[xx], E[xy]) are
//   d/dmu_x = 2 mu_y (A2 - A1) / (B1 B2) - map (2 mu_x / B1 - 2 mu_x / B2),  d/dE[xx] = -map / B2,
//   d/dE[xy] = 2 A1 / (B1 B2);
// the window is symmetric so the adjoint of the convolution is the same convolution, giving
//   dL/dx = w*(g d_mu) + 2 x w*(g d_exx) + y w*(g d_exy).
#include "train/ssim.h"

#include <cmath>

namespace hgs::train {
namespace {

constexpr int kWin = 11, kHalf = 5;

template <typename T>
struct Window {
  T w[kWin];
  Window() {
    double s = 0, v[kWin];
    for (int i = 0; i < kWin; ++i) s += v[i] = std::exp(-double((i - kHalf) * (i - kHalf)) / (2 * 1.5 * 1.5));
    for (int i = 0; i < kWin; ++i) w[i] = T(v[i] / s);
  }
};

// out = w (x) w convolution of `in` [H, W*C] along rows (stride C) and columns; `tmp` [H, W*C].
template <typename T>
void conv_same(const T* in, T* out, T* tmp, int H, int W, int C) {
  const T* w = ssim_window<T>();
  const int L = W * C;
#pragma omp parallel
  {
#pragma omp for schedule(static)
    for (int y = 0; y < H; ++y) {
      const T* r = in + size_t(y) * L;
      T* o = tmp + size_t(y) * L;
      const int lo = kHalf * C, hi = L - kHalf * C;
      for (int j = 0; j < std::min(lo, L); ++j) {
        T s = 0;
        for (int k = 0; k < kWin; ++k) {
          int q = j + (k - kHalf) * C;
          if (q >= 0 && q < L) s += w[k] * r[q];
        }
        o[j] = s;
      }
      // Interior: taps outer, pixels inner (contiguous, vectorised over j).
      if (hi > lo) {
        const T w0 = w[0];
#pragma omp simd
        for (int j = lo; j < hi; ++j) o[j] = w0 * r[j - kHalf * C];
        for (int k = 1; k < kWin; ++k) {
          const T wk = w[k];
          const T* rk = r + (k - kHalf) * C;
#pragma omp simd
          for (int j = lo; j < hi; ++j) o[j] += wk * rk[j];
        }
      }
      for (int j = std::max(hi, lo); j < L; ++j) {
        T s = 0;
        for (int k = 0; k < kWin; ++k) {
          int q = j + (k - kHalf) * C;
          if (q >= 0 && q < L) s += w[k] * r[q];
        }
        o[j] = s;
      }
    }
#pragma omp for schedule(static)
    for (int y = 0; y < H; ++y) {
      T* o = out + size_t(y) * L;
      int k0 = std::max(0, kHalf - y), k1 = std::min(kWin, H + kHalf - y);
      {
        const T* r = tmp + size_t(y + k0 - kHalf) * L;
        const T wk = w[k0];
#pragma omp simd
        for (int j = 0; j < L; ++j) o[j] = wk * r[j];
      }
      for (int k = k0 + 1; k < k1; ++k) {
        const T* r = tmp + size_t(y + k - kHalf) * L;
        const T wk = w[k];
#pragma omp simd
        for (int j = 0; j < L; ++j) o[j] += wk * r[j];
      }
    }
  }
}

}  // namespace

template <typename T>
const T* ssim_window() {
  static const Window<T> win;
  return win.w;
}

template <typename T>
T ssim(const T* x, const T* y, int H, int W, int C, T* grad_x, SsimWorkspace<T>& ws) {
  const size_t n = size_t(H) * W * C;
  const T C1 = T(0.01 * 0.01), C2 = T(0.03 * 0.03);
  for (auto* v : {&ws.mx, &ws.my, &ws.exx, &ws.eyy, &ws.exy, &ws.tmp})
    if (v->size() != n) v->resize(n);
  // Products (into the output buffers, then convolved in place through tmp).
  T *mx = ws.mx.data(), *my = ws.my.data(), *exx = ws.exx.data(), *eyy = ws.eyy.data(), *exy = ws.exy.data();
  T* tmp = ws.tmp.data();
#pragma omp parallel for simd schedule(static)
  for (size_t i = 0; i < n; ++i) {
    exx[i] = x[i] * x[i];
    eyy[i] = y[i] * y[i];
    exy[i] = x[i] * y[i];
  }
  conv_same(x, mx, tmp, H, W, C);
  conv_same(y, my, tmp, H, W, C);
  conv_same(exx, exx, tmp, H, W, C);
  conv_same(eyy, eyy, tmp, H, W, C);
  conv_same(exy, exy, tmp, H, W, C);
  const T g = T(1) / T(n);
  double total = 0;
#pragma omp parallel for simd reduction(+ : total) schedule(static)
  for (size_t i = 0; i < n; ++i) {
    T mu1 = mx[i], mu2 = my[i];
    T s11 = exx[i] - mu1 * mu1, s22 = eyy[i] - mu2 * mu2, s12 = exy[i] - mu1 * mu2;
    T A1 = 2 * mu1 * mu2 + C1, A2 = 2 * s12 + C2, B1 = mu1 * mu1 + mu2 * mu2 + C1, B2 = s11 + s22 + C2;
    T inv = T(1) / (B1 * B2);
    T map = A1 * A2 * inv;
    total += map;
    if (grad_x) {
      // Reuse the buffers: mx <- g d/dmu_x, exx <- g d/dE[xx], exy <- g d/dE[xy].
      mx[i] = g * (2 * mu2 * (A2 - A1) * inv - map * (2 * mu1 / B1 - 2 * mu1 / B2));
      exx[i] = -g * map / B2;
      exy[i] = g * 2 * A1 * inv;
    }
  }
  if (grad_x) {
    conv_same(mx, mx, tmp, H, W, C);
    conv_same(exx, exx, tmp, H, W, C);
    conv_same(exy, exy, tmp, H, W, C);
#pragma omp parallel for simd schedule(static)
    for (size_t i = 0; i < n; ++i) grad_x[i] = mx[i] + 2 * x[i] * exx[i] + y[i] * exy[i];
  }
  return T(total / double(n));
}

template float ssim<float>(const float*, const float*, int, int, int, float*, SsimWorkspace<float>&);
template double ssim<double>(const double*, const double*, int, int, int, double*, SsimWorkspace<double>&);
template const float* ssim_window<float>();
template const double* ssim_window<double>();

}  // namespace hgs::train
