#include "hybrid/bro.h"

#include <algorithm>
#include <cmath>

namespace hgs::hybrid {
namespace {

template <bool kMax>
void filter(const float* in, int H, int W, int s, float* out, std::vector<float>& row) {
  const int r = s / 2, r2 = s - 1 - r;  // window [x - r, x + r2] (centred for odd s)
  row.resize(size_t(H) * W);
  auto pick = [](float a, float b) { return kMax ? std::max(a, b) : std::min(a, b); };
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      float v = in[size_t(y) * W + x];
      for (int d = std::max(0, x - r); d <= std::min(W - 1, x + r2); ++d) v = pick(v, in[size_t(y) * W + d]);
      row[size_t(y) * W + x] = v;
    }
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      float v = row[size_t(y) * W + x];
      for (int d = std::max(0, y - r); d <= std::min(H - 1, y + r2); ++d) v = pick(v, row[size_t(d) * W + x]);
      out[size_t(y) * W + x] = v;
    }
}

}  // namespace

void dilate(const float* in, int H, int W, int s, float* out) {
  std::vector<float> row;
  filter<true>(in, H, W, s, out, row);
}
void erode(const float* in, int H, int W, int s, float* out) {
  std::vector<float> row;
  filter<false>(in, H, W, s, out, row);
}

void boundary_band(const float* A, const float* M, int H, int W, int s, float* B, std::vector<float>& tmp) {
  const size_t n = size_t(H) * W;
  tmp.resize(3 * n);
  float *d = tmp.data(), *e = tmp.data() + n;
  std::vector<float> row;
  filter<true>(A, H, W, s, d, row);
  filter<false>(A, H, W, s, e, row);
  for (size_t i = 0; i < n; ++i) B[i] = d[i] - e[i];
  filter<true>(M, H, W, s, d, row);
  filter<false>(M, H, W, s, e, row);
  for (size_t i = 0; i < n; ++i) B[i] = std::clamp(B[i] + d[i] - e[i], 0.f, 1.f);
}

template <class T>
T bro_loss(const T* pred, const T* gt, int cs, int C, const float* B, int H, int W, T eps, T* grad, T scale) {
  // Weight total first (it is the normaliser of every term).
  double wsum = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float b = B[size_t(y) * W + x];
      if (x + 1 < W) wsum += std::max(b, B[size_t(y) * W + x + 1]);
      if (y + 1 < H) wsum += std::max(b, B[size_t(y + 1) * W + x]);
    }
  const T den = T(C * wsum) + eps;
  double num = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const size_t p = size_t(y) * W + x;
      const float b = B[p];
      for (int dir = 0; dir < 2; ++dir) {
        if (dir == 0 ? x + 1 >= W : y + 1 >= H) continue;
        const size_t q = dir == 0 ? p + 1 : p + W;
        const T w = T(std::max(b, B[q]));
        if (w == T(0)) continue;
        for (int c = 0; c < C; ++c) {
          const T r = (pred[q * cs + c] - pred[p * cs + c]) - (gt[q * cs + c] - gt[p * cs + c]);
          num += double(w * std::abs(r));
          if (grad && r != T(0)) {
            const T g = scale * w * (r > 0 ? T(1) : T(-1)) / den;
            grad[q * cs + c] += g;
            grad[p * cs + c] -= g;
          }
        }
      }
    }
  return T(num) / den;
}

template float bro_loss<float>(const float*, const float*, int, int, const float*, int, int, float, float*, float);
template double bro_loss<double>(const double*, const double*, int, int, const float*, int, int, double, double*, double);

}  // namespace hgs::hybrid
