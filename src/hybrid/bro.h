// Boundary Reconstruction Optimization (paper eqs. 11-14).
//
// For one view u and object k:
//   B^pred = D(A^pred) - E(A^pred),  B^gt = D(M) - E(M),  B = clip(B^pred + B^gt, 0, 1)      (eqs. 12-13)
// with D / E the grey-scale dilation / erosion (max / min filter) by an s x s square (default 5; pixels
// outside the image are ignored). The forward differences are Dx I(x, y) = I(x+1, y) - I(x, y) and
// Dy I(x, y) = I(x, y+1) - I(x, y); their weights are the band over each difference's support:
// W^x(x, y) = max(B(x, y), B(x+1, y)), W^y(x, y) = max(B(x, y), B(x, y+1)). Then              (eq. 14)
//   L = sum_d || W^d (Dd I^pred - Dd I^gt) ||_1 / (C sum_d ||W^d||_1 + eps).
// B is treated as a constant: no gradient flows through the morphology or into A^pred (the band only
// selects where the loss looks), so the gradient goes to I^pred alone.
#pragma once
#include <vector>

namespace hgs::hybrid {

// Grey-scale dilation (max filter) and erosion (min filter) with an s x s square, separable.
// in, out: [H, W]
void dilate(const float* in, int H, int W, int s, float* out);
void erode(const float* in, int H, int W, int s, float* out);

// B = clip(D(A) - E(A) + D(M) - E(M), 0, 1). A, M, B: [H, W]; `tmp` scratch of 2 H W floats.
void boundary_band(const float* A, const float* M, int H, int W, int s, float* B, std::vector<float>& tmp);

// Eq. 14 for images with C channels. pred, gt: [H, W, C] (channel stride `cstride` >= C, channels at
// offset 0 of each pixel block), B: [H, W]. grad (may be null) receives scale * dL/dpred added into
// [H, W, cstride]. Returns L.
template <class T>
T bro_loss(const T* pred, const T* gt, int cstride, int C, const float* B, int H, int W, T eps, T* grad, T scale);

}  // namespace hgs::hybrid
