#include "hybrid/bro.h"

#include <algorithm>
#include <cmath>

namespace hgs::hybrid {
namespace {

// Separable max and min filters over the window [x - r, x + r2] clipped to the image (centred for odd s): each
// pass is a max / min of whole shifted rows, so the inner loops are contiguous and vectorise. The window's values
// are taken in one order everywhere (the pixel's own, then the others from the lowest), so that the image's
// filter (minmax_filter) and the row by row one (BandRows) give the same bits.
// Horizontal: row src [W] -> hi, lo [W].
void minmax_row(const float* src, int W, int r, int r2, float* hi, float* lo) {
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

// Vertical, output row y of H: the horizontal filters' rows by row(d) (max row, min row), into hi, lo [W].
template <class RowPair>
void minmax_col(const RowPair& row, int y, int H, int W, int r, int r2, float* hi, float* lo) {
  const auto own = row(y);
  std::copy(own.first, own.first + W, hi);
  std::copy(own.second, own.second + W, lo);
  for (int d = std::max(0, y - r); d <= std::min(H - 1, y + r2); ++d) {
    if (d == y) continue;
    const auto o = row(d);
    const float *shi = o.first, *slo = o.second;
#pragma omp simd
    for (int x = 0; x < W; ++x) {
      hi[x] = std::max(hi[x], shi[x]);
      lo[x] = std::min(lo[x], slo[x]);
    }
  }
}

// The whole image: dmax, dmin [H, W] out, rmax, rmin [H, W] scratch.
void minmax_filter(const float* in, int H, int W, int s, float* dmax, float* dmin, float* rmax, float* rmin) {
  const int r = s / 2, r2 = s - 1 - r;  // window [x - r, x + r2]
  for (int y = 0; y < H; ++y) minmax_row(in + size_t(y) * W, W, r, r2, rmax + size_t(y) * W, rmin + size_t(y) * W);
  const auto row = [&](int d) {
    return std::pair<const float*, const float*>(rmax + size_t(d) * W, rmin + size_t(d) * W);
  };
  for (int y = 0; y < H; ++y) minmax_col(row, y, H, W, r, r2, dmax + size_t(y) * W, dmin + size_t(y) * W);
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

void boundary_band(const float* A, const float* M, int H, int W, int s, float* B) {
  BandRows rows;
  rows.reset(H, W, s);
  const BandRows::Row a = [&](int y) { return A + size_t(y) * W; }, m = [&](int y) { return M + size_t(y) * W; };
  for (int y = 0; y < H; ++y) {
    const float* b = rows.row(y, a, m);
    std::copy(b, b + W, B + size_t(y) * W);
  }
}

void BandRows::reset(int H, int W, int s) {
  H_ = H, W_ = W, s_ = std::max(1, s), next_ = -1;
  ring_.resize(size_t(s_) * 4 * W);
  out_.resize(2 * size_t(W));
}

const float* BandRows::row(int y, const Row& A, const Row& M) {
  const int W = W_, r = s_ / 2, r2 = s_ - 1 - r;
  auto slot = [&](int d) { return &ring_[size_t(d % s_) * 4 * W]; };
  if (next_ < 0) next_ = std::max(0, y - r);
  for (; next_ <= std::min(H_ - 1, y + r2); ++next_) {
    float* o = slot(next_);
    minmax_row(A(next_), W, r, r2, o, o + W);
    minmax_row(M(next_), W, r, r2, o + 2 * W, o + 3 * W);
  }
  float* b = &out_[size_t(y & 1) * W];
  std::vector<float>& t = tmp_;
  t.resize(4 * size_t(W));
  float *d = t.data(), *e = d + W, *dm = e + W, *em = dm + W;
  minmax_col([&](int k) { return std::pair<const float*, const float*>(slot(k), slot(k) + W); }, y, H_, W, r, r2, d, e);
  minmax_col([&](int k) { return std::pair<const float*, const float*>(slot(k) + 2 * W, slot(k) + 3 * W); }, y, H_, W,
             r, r2, dm, em);
  for (int x = 0; x < W; ++x) b[x] = d[x] - e[x];
  for (int x = 0; x < W; ++x) b[x] = std::clamp(b[x] + dm[x] - em[x], 0.f, 1.f);
  return b;
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
// max(B(x, y), B(x, y + 1)) (0 past the last column / row). b, bn: rows y and y + 1 of B [W] (bn null: y is the
// last row); wx, wy [W * C].
template <class T, int kC>
void pair_weights_c(const float* b, const float* bn, int W, int C, T* wx, T* wy) {
  const int nc = kC > 0 ? kC : C;
  for (int x = 0; x < W; ++x) {
    const float bx = b[x];
    const T vx = x + 1 < W ? T(std::max(bx, b[x + 1])) : T(0);
    const T vy = bn ? T(std::max(bx, bn[x])) : T(0);
#pragma GCC unroll 4
    for (int c = 0; c < nc; ++c) {
      wx[size_t(x) * nc + c] = vx;
      wy[size_t(x) * nc + c] = vy;
    }
  }
}

template <class T>
void pair_weights(const float* b, const float* bn, int W, int C, T* wx, T* wy) {
  if (C == 3) return pair_weights_c<T, 3>(b, bn, W, C, wx, wy);  // the colour images of eq. 14
  if (C == 1) return pair_weights_c<T, 1>(b, bn, W, C, wx, wy);
  pair_weights_c<T, 0>(b, bn, W, C, wx, wy);
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
    pair_weights(B + size_t(y) * W, y + 1 < H ? B + size_t(y + 1) * W : nullptr, W, C, wx.data(), wy.data());
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
// from 0: one pass per row writes the row's values and keeps its y pairs for the next row (no zeroing pass, and
// each term is added exactly where the per-direction loops added it, so the same bits).
template <class T>
void BroRows<T>::reset(int W, int C) {
  W_ = W, C_ = C, first_ = true;
  for (auto* v : {&wx_, &wy_, &ax_, &ay_, &gx_, &gy_, &carry_}) v->assign(size_t(W) * C, T(0));
}

template <class T>
void BroRows<T>::row(const T* p, const T* q, const float* b0, const T* p1, const T* q1, const float* b1, double* wsum,
                     double* num, T* u) {
  const int W = W_, C = C_, L = W * C, X = L - C;  // the x pairs start at elements [0, X)
  const bool next = p1 != nullptr, first = first_;
  first_ = false;
  pair_weights(b0, next ? b1 : nullptr, W, C, wx_.data(), wy_.data());
  T *wx = wx_.data(), *wy = wy_.data(), *ax = ax_.data(), *ay = ay_.data(), *gx = gx_.data(), *gy = gy_.data();
  T* carry = carry_.data();
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
      const T r = (p1[i] - p[i]) - (q1[i] - q[i]);
      ay[i] = wy[i] * std::abs(r);
      gy[i] = wy[i] * T((r > 0) - (r < 0));
    }
  } else {
    std::fill(ay, ay + L, T(0));
  }
  // The row's unit values: elements [0, C) have no left pair, [X, L) no own x pair (W = 1: neither).
  auto finish = [&](int i0, int i1, bool own_x, bool left_x) {
#pragma omp simd
    for (int i = i0; i < i1; ++i) {
      T v = first ? T(0) : carry[i];
      if (own_x) v -= gx[i];
      if (left_x) v += gx[i - C];
      if (next) {
        v -= gy[i];
        carry[i] = T(0) + gy[i];
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
    wsum[x] = double(wx[i]) + double(wy[i]);
    num[x] = ns;
  }
}

template <class T>
void bro_parts(const T* pred, const T* gt, int C, const float* B, int H, int W, double* wsum, double* num, T* unit) {
  const size_t L = size_t(W) * C;
  BroRows<T> rows;
  rows.reset(W, C);
  for (int y = 0; y < H; ++y) {
    const bool next = y + 1 < H;
    rows.row(pred + y * L, gt + y * L, B + size_t(y) * W, next ? pred + (y + 1) * L : nullptr,
             next ? gt + (y + 1) * L : nullptr, next ? B + size_t(y + 1) * W : nullptr, wsum + size_t(y) * W,
             num + size_t(y) * W, unit + y * L);
  }
}

template class BroRows<float>;
template class BroRows<double>;
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
