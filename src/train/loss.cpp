// L1 + D-SSIM loss: one pass computes L1, its sign gradient and the MSE (for PSNR); SSIM comes from
// train/ssim.cpp and its gradient is blended into the same buffer.
#include "train/loss.h"

#include <cmath>

namespace hgs::train {

template <typename T>
T l1_loss(const T* a, const T* b, size_t n, T* grad, T scale) {
  double s = 0;
  const T g = scale / T(n);
#pragma omp parallel for simd reduction(+ : s) schedule(static)
  for (size_t i = 0; i < n; ++i) {
    T d = a[i] - b[i];
    s += std::abs(d);
    if (grad) grad[i] = d > 0 ? g : (d < 0 ? -g : T(0));
  }
  return T(s / double(n));
}

template float l1_loss<float>(const float*, const float*, size_t, float*, float);
template double l1_loss<double>(const double*, const double*, size_t, double*, double);

LossValues PhotometricLoss::operator()(const float* render, const float* gt, int H, int W, float* grad) {
  const size_t n = size_t(H) * W * 3;
  LossValues v;
  float* gs = nullptr;
  if (grad) {
    if (g_ssim_.size() != n) g_ssim_.resize(n);
    gs = g_ssim_.data();
  }
  v.ssim = ssim(render, gt, H, W, 3, gs, ws_);
  double l1 = 0, se = 0;
  const float a = (1 - lambda_) / float(n), b = -lambda_;
#pragma omp parallel for simd reduction(+ : l1, se) schedule(static)
  for (size_t i = 0; i < n; ++i) {
    float d = render[i] - gt[i];
    l1 += std::abs(d);
    se += double(d) * d;
    if (grad) grad[i] = (d > 0 ? a : (d < 0 ? -a : 0.f)) + b * gs[i];
  }
  v.l1 = float(l1 / double(n));
  v.mse = float(se / double(n));
  v.total = (1 - lambda_) * v.l1 + lambda_ * (1 - v.ssim);
  return v;
}

}  // namespace hgs::train
