#include "hybrid/bro.h"

#include <algorithm>
#include <cmath>

namespace hgs::hybrid {
namespace {

// Separable max and min filters over the window [x - r, x + r2] clipped to the image (centred for odd s), both in
// one pass over the image: dmax, dmin [H, W] out, rmax, rmin [H, W] scratch. Each pass is a max / min of whole
// shifted rows, so the inner loops are contiguous and vectorise.
void minmax_filter(const float* in, int H, int W, int s, float* dmax, float* dmin, float* rmax, float* rmin) {
  const int r = s / 2, r2 = s - 1 - r;  // window [x - r, x + r2]
  for (int y = 0; y < H; ++y) {
    const float* src = in + size_t(y) * W;
    float* hi = rmax + size_t(y) * W;
    float* lo = rmin + size_t(y) * W;
    std::copy(src, src + W, hi);
    std::copy(src, src + W, lo);
    for (int d = -r; d <= r2; ++d) {
      if (d == 0) continue;
      const int x0 = std::max(0, -d), x1 = std::min(W, W - d);
#pragma omp simd
      for (int x = x0; x < x1; ++x) {
        hi[x] = std::max(hi[x], src[x + d]);
        lo[x] = std::min(lo[x], src[x + d]);
      }
    }
  }
  for (int y = 0; y < H; ++y) {
    float* hi = dmax + size_t(y) * W;
    float* lo = dmin + size_t(y) * W;
    std::copy(rmax + size_t(y) * W, rmax + size_t(y + 1) * W, hi);
    std::copy(rmin + size_t(y) * W, rmin + size_t(y + 1) * W, lo);
    for (int d = std::max(0, y - r); d <= std::min(H - 1, y + r2); ++d) {
      if (d == y) continue;
      const float* shi = rmax + size_t(d) * W;
      const float* slo = rmin + size_t(d) * W;
#pragma omp simd
      for (int x = 0; x < W; ++x) {
        hi[x] = std::max(hi[x], shi[x]);
        lo[x] = std::min(lo[x], slo[x]);
      }
    }
  }
}

}  // namespace

// Dilation and erosion alone (tests and diagnostics): the pair's filter, the other output discarded.
void dilate(const float* in, int H, int W, int s, float* out) {
  std::vector<float> tmp(3 * size_t(H) * W);
  minmax_filter(in, H, W, s, out, tmp.data(), tmp.data() + size_t(H) * W, tmp.data() + 2 * size_t(H) * W);
}
void erode(const float* in, int H, int W, int s, float* out) {
  std::vector<float> tmp(3 * size_t(H) * W);
  minmax_filter(in, H, W, s, tmp.data(), out, tmp.data() + size_t(H) * W, tmp.data() + 2 * size_t(H) * W);
}

void boundary_band(const float* A, const float* M, int H, int W, int s, float* B, std::vector<float>& tmp) {
  const size_t n = size_t(H) * W;
  tmp.resize(4 * n);
  float *d = tmp.data(), *e = d + n, *rd = e + n, *re = rd + n;
  minmax_filter(A, H, W, s, d, e, rd, re);
  for (size_t i = 0; i < n; ++i) B[i] = d[i] - e[i];
  minmax_filter(M, H, W, s, d, e, rd, re);
  for (size_t i = 0; i < n; ++i) B[i] = std::clamp(B[i] + d[i] - e[i], 0.f, 1.f);
}

// sum_d ||W^d||_1 of eq. 14 (the normaliser of every term): W^x and W^y summed over the differences' supports.
double band_weight_total(const float* B, int H, int W) {
  double wsum = 0;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x) {
      const float b = B[size_t(y) * W + x];
      if (x + 1 < W) wsum += std::max(b, B[size_t(y) * W + x + 1]);
      if (y + 1 < H) wsum += std::max(b, B[size_t(y + 1) * W + x]);
    }
  return wsum;
}

namespace {

// Contiguous channels (cs == C): the pairs of both directions are differences of whole shifted rows, computed
// branch-free with the per-pixel weight spread over the channels (same sums as the generic loop below, which
// serves strided layouts).
// Row y's pair weights, each repeated over the C channels: wx[x, c] = max(B(x, y), B(x + 1, y)) and wy[x, c] =
// max(B(x, y), B(x, y + 1)) (0 past the last column / row). B [H, W]; wx, wy [W * C].
template <class T, int kC>
void pair_weights_c(const float* b, bool next_row, int W, T* wx, T* wy) {
  for (int x = 0; x < W; ++x) {
    const float bx = b[x];
    const T vx = x + 1 < W ? T(std::max(bx, b[x + 1])) : T(0);
    const T vy = next_row ? T(std::max(bx, b[x + W])) : T(0);
#pragma GCC unroll 4
    for (int c = 0; c < kC; ++c) {
      wx[size_t(x) * kC + c] = vx;
      wy[size_t(x) * kC + c] = vy;
    }
  }
}

template <class T>
void pair_weights(const float* B, int y, int H, int W, int C, T* wx, T* wy) {
  const float* b = B + size_t(y) * W;
  const bool next_row = y + 1 < H;
  if (C == 3) return pair_weights_c<T, 3>(b, next_row, W, wx, wy);  // the colour images of eq. 14
  if (C == 1) return pair_weights_c<T, 1>(b, next_row, W, wx, wy);
  for (int x = 0; x < W; ++x)
    for (int c = 0; c < C; ++c) {
      wx[size_t(x) * C + c] = x + 1 < W ? T(std::max(b[x], b[x + 1])) : T(0);
      wy[size_t(x) * C + c] = next_row ? T(std::max(b[x], b[x + W])) : T(0);
    }
}

template <class T>
T bro_loss_contiguous(const T* pred, const T* gt, int C, const float* B, int H, int W, T eps, T* grad, T scale,
                      double band_total) {
  const int L = W * C;
  std::vector<T> wx(L), wy(L), g(L);
  const T den = T(C * band_total) + eps;
  const T gs = scale / den;
  double num = 0;
  for (int y = 0; y < H; ++y) {
    pair_weights(B, y, H, W, C, wx.data(), wy.data());
    const T* p = pred + size_t(y) * L;
    const T* q = gt + size_t(y) * L;
    // x direction: element i pairs with i + C in the same row.
    double sx = 0;
#pragma omp simd reduction(+ : sx)
    for (int i = 0; i < L - C; ++i) {
      const T r = (p[i + C] - p[i]) - (q[i + C] - q[i]);
      const T w = wx[i];
      sx += double(w * std::abs(r));
      g[i] = gs * w * T((r > 0) - (r < 0));
    }
    num += sx;
    if (grad) {
      T* gr = grad + size_t(y) * L;
      for (int i = 0; i < L - C; ++i) gr[i] -= g[i];
      for (int i = 0; i < L - C; ++i) gr[i + C] += g[i];
    }
    if (y + 1 >= H) continue;
    // y direction: element i pairs with the same element of the next row.
    double sy = 0;
#pragma omp simd reduction(+ : sy)
    for (int i = 0; i < L; ++i) {
      const T r = (p[i + L] - p[i]) - (q[i + L] - q[i]);
      const T w = wy[i];
      sy += double(w * std::abs(r));
      g[i] = gs * w * T((r > 0) - (r < 0));
    }
    num += sy;
    if (grad) {
      T* gr = grad + size_t(y) * L;
#pragma omp simd
      for (int i = 0; i < L; ++i) {
        gr[i] -= g[i];
        gr[i + L] += g[i];
      }
    }
  }
  return T(num) / den;
}

}  // namespace

template <class T>
T bro_loss(const T* pred, const T* gt, int cs, int C, const float* B, int H, int W, T eps, T* grad, T scale,
           double band_total) {
  if (band_total < 0) band_total = band_weight_total(B, H, W);
  if (cs == C) return bro_loss_contiguous(pred, gt, C, B, H, W, eps, grad, scale, band_total);
  const T den = T(C * band_total) + eps;
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

// Row by row as bro_loss_contiguous: each direction's differences of whole shifted rows, branch-free; the
// per-element terms are then summed per pixel. A value of `unit` gets, in this order, the previous row's y pair
// (+), its own x pair (-), its left neighbour's x pair (+) and its own y pair (-), each added to the running value
// from 0: one pass per row writes the row's values and starts the next row's (no zeroing pass, and each term is
// added exactly where the per-direction loops added it, so the same bits).
template <class T>
void bro_parts(const T* pred, const T* gt, int C, const float* B, int H, int W, double* wsum, double* num, T* unit) {
  const int L = W * C, X = L - C;  // the x pairs start at elements [0, X)
  std::vector<T> wx(L), wy(L), ax(L, T(0)), ay(L, T(0)), gx(L), gy(L);
  for (int y = 0; y < H; ++y) {
    pair_weights(B, y, H, W, C, wx.data(), wy.data());
    const T* p = pred + size_t(y) * L;
    const T* q = gt + size_t(y) * L;
    T* u = unit + size_t(y) * L;
    const bool next = y + 1 < H;
    // x direction: element i pairs with i + C in the same row.
#pragma omp simd
    for (int i = 0; i < X; ++i) {
      const T r = (p[i + C] - p[i]) - (q[i + C] - q[i]);
      ax[i] = wx[i] * std::abs(r);
      gx[i] = wx[i] * T((r > 0) - (r < 0));
    }
    // y direction: element i pairs with the same element of the next row.
    if (next) {
#pragma omp simd
      for (int i = 0; i < L; ++i) {
        const T r = (p[i + L] - p[i]) - (q[i + L] - q[i]);
        ay[i] = wy[i] * std::abs(r);
        gy[i] = wy[i] * T((r > 0) - (r < 0));
      }
    } else {
      std::fill(ay.begin(), ay.end(), T(0));
    }
    // The row's unit values: elements [0, C) have no left pair, [X, L) no own x pair (W = 1: neither).
    const T* g0 = gx.data();
    auto finish = [&](int i0, int i1, bool own_x, bool left_x) {
#pragma omp simd
      for (int i = i0; i < i1; ++i) {
        T v = y == 0 ? T(0) : u[i];
        if (own_x) v -= g0[i];
        if (left_x) v += g0[i - C];
        if (next) {
          v -= gy[i];
          u[i + L] = T(0) + gy[i];
        }
        u[i] = v;
      }
    };
    if (W == 1) {
      finish(0, L, false, false);
    } else {
      finish(0, C, true, false);
      finish(C, X, true, true);
      finish(X, L, false, true);
    }
    for (int x = 0; x < W; ++x) {
      const size_t i = size_t(x) * C;
      double ns = 0;
      for (int c = 0; c < C; ++c) ns += double(ax[i + c]) + double(ay[i + c]);
      wsum[size_t(y) * W + x] = double(wx[i]) + double(wy[i]);
      num[size_t(y) * W + x] = ns;
    }
  }
}

template <class T>
void remove_scale_component(const T* p, size_t n, T* g) {
  double gp = 0, pp = 0;
  for (size_t i = 0; i < n; ++i) {
    gp += double(g[i]) * double(p[i]);
    pp += double(p[i]) * double(p[i]);
  }
  if (!(pp > 0)) return;
  const T a = T(gp / pp);
  for (size_t i = 0; i < n; ++i) g[i] -= a * p[i];
}

template void bro_parts<float>(const float*, const float*, int, const float*, int, int, double*, double*, float*);
template void bro_parts<double>(const double*, const double*, int, const float*, int, int, double*, double*, double*);
template void remove_scale_component<float>(const float*, size_t, float*);
template void remove_scale_component<double>(const double*, size_t, double*);
template float bro_loss<float>(const float*, const float*, int, int, const float*, int, int, float, float*, float,
                               double);
template double bro_loss<double>(const double*, const double*, int, int, const float*, int, int, double, double*,
                                 double, double);

}  // namespace hgs::hybrid
