// Photometric loss of 3DGS: L = (1 - lambda) L1 + lambda (1 - SSIM), lambda = 0.2, with its exact gradient
// with respect to the rendered image. L1 is the mean absolute difference over all pixels and channels; its
// derivative at an exact tie is 0 (as torch's abs).
#pragma once
#include <cmath>
#include <cstddef>
#include <vector>

#include "train/ssim.h"

namespace hgs::train {

struct LossValues {
  float total = 0, l1 = 0, ssim = 0, mse = 0;
};

// Mean absolute difference of a and b, [n]; when `grad` is not null it receives scale * sign(a - b) / n.
template <typename T>
T l1_loss(const T* a, const T* b, size_t n, T* grad, T scale = T(1));

class PhotometricLoss {
 public:
  explicit PhotometricLoss(float lambda_dssim = 0.2f) : lambda_(lambda_dssim) {}
  // render, gt, grad: [H, W, 3]. `grad` (may be null) receives dL/drender. No allocation once warm.
  LossValues operator()(const float* render, const float* gt, int H, int W, float* grad);

 private:
  float lambda_;
  SsimWorkspace<float> ws_;
  std::vector<float> g_ssim_;  // [H, W, 3]
};

inline float psnr_from_mse(double mse) { return mse > 0 ? float(-10.0 * std::log10(mse)) : 99.f; }

}  // namespace hgs::train
