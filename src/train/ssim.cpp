// SSIM forward and exact backward with separable convolutions.
// Forward: the five local moments mu_x = w*x, mu_y = w*y, E[xx] = w*x^2, E[yy] = w*y^2, E[xy] = w*(xy) are
// 11-tap horizontal then vertical passes (zero padding). With A1 = 2 mu_x mu_y + C1, A2 = 2 s_xy + C2,
// B1 = mu_x^2 + mu_y^2 + C1, B2 = s_xx + s_yy + C2 (s_xx = E[xx] - mu_x^2, s_xy = E[xy] - mu_x mu_y) the map is
// A1 A2 / (B1 B2). Backward: with g = 1/(HWC), the map's partials in (mu_x, E[xx], E[xy]) are
//   d/dmu_x = 2 mu_y (A2 - A1) / (B1 B2) - map (2 mu_x / B1 - 2 mu_x / B2),  d/dE[xx] = -map / B2,
//   d/dE[xy] = 2 A1 / (B1 B2);
// the window is symmetric so the adjoint of the convolution is the same convolution, giving
//   dL/dx = w*(g d_mu) + 2 x w*(g d_exx) + y w*(g d_exy).
// ssim_map also stores the map and takes g = 1/count from the caller (a crop scored as part of a larger image);
// with y null (an all-zero y) the passes of mu_y, E[yy], E[xy] and of d_exy are skipped (their values are 0), and
// with a support given (ssim_map_rows' `ys`: where y may be non-zero) they run only on and near it.
// ssim_rows_streamed runs the same passes as one line-buffer pipeline from x and y to the gradient rows: the
// coefficients in a ring of 11 rows, each gradient row handed out as soon as its 11 coefficient rows exist.
#include "train/ssim.h"

#include <omp.h>

#include <algorithm>
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

// Horizontal 11-tap pass of one row `r` [W*C] (channel stride C, zero padding) into `o`: outputs [j0, j1) with
// the 11 taps summed in registers, vectorised over j (one store per output). r0 is the row shifted so that
// r0[j + k C] is tap k of output j.
template <typename T>
inline void conv_taps(const T* r0, T* o, int j0, int j1, int C, const T* wk) {
#pragma omp simd
  for (int j = j0; j < j1; ++j) {
    T acc = wk[0] * r0[j];
#pragma GCC unroll 11
    for (int k = 1; k < kWin; ++k) acc += wk[k] * r0[j + k * C];
    o[j] = acc;
  }
}

inline float fused(float a, float b, float c) { return __builtin_fmaf(a, b, c); }
inline double fused(double a, double b, double c) { return __builtin_fma(a, b, c); }

// The outputs near the row's ends, whose windows pass its edge: the sum from 0 of the taps inside the row, each
// one fused multiply-add in tap order. r0 as for conv_taps, with zeros outside the row: a zero tap adds w * 0 to
// a sum that is never -0, which leaves it unchanged, so these are the sums over the inside taps alone.
template <typename T>
inline void conv_end_taps(const T* r0, T* o, int n, int C, const T* wk) {
#pragma omp simd
  for (int j = 0; j < n; ++j) {
    T acc = T(0);
#pragma GCC unroll 11
    for (int k = 0; k < kWin; ++k) acc = fused(wk[k], r0[j + k * C], acc);
    o[j] = acc;
  }
}

// Outputs [j0, j1) of the horizontal pass of row r [W*C] (channel stride C, zero padding) into o, bitwise what
// the pass over the whole row gives them (each output has its own arithmetic: the interior's conv_taps, the end
// taps within 5 C of the row's ends, so a part of a row is computed as the whole row computes it); reads r only
// in [j0 - 5 C, j1 + 5 C).
template <typename T>
void conv_row_range(const T* r, T* o, int W, int C, int j0, int j1) {
  const T* w = ssim_window<T>();
  const int L = W * C, lo = kHalf * C, hi = L - kHalf * C;
  j0 = std::max(0, j0);
  j1 = std::min(L, j1);
  if (j0 >= j1) return;
  T wk[kWin];
  for (int k = 0; k < kWin; ++k) wk[k] = w[k];
  constexpr int kMaxPadC = 8;
  if (hi > lo && C <= kMaxPadC) {
    // The 5 C outputs at each end, vectorised on a copy of the row's end with the padding's zeros in place (the
    // same sums as the scalar loops below, bitwise). Narrow crops have many rows and few columns: scalar ends
    // with a test per tap were a third of this pass there. Output i of an end reads pad[i, i + 10 C].
    T pad[3 * kHalf * kMaxPadC];
    if (j0 < lo) {  // left end: pad[i] = r[i - 5 C]
      const int e = std::min(j1, lo);
      for (int i = j0; i < e + 2 * lo; ++i) pad[i] = i >= lo ? r[i - lo] : T(0);
      conv_end_taps(pad + j0, o + j0, e - j0, C, wk);
    }
    if (std::min(j1, hi) > std::max(j0, lo)) conv_taps(r - kHalf * C, o, std::max(j0, lo), std::min(j1, hi), C, wk);
    if (j1 > hi) {  // right end: pad[i] = r[hi - 5 C + i]
      const int s0 = std::max(j0, hi) - hi, e = j1 - hi;
      for (int i = s0; i < e + 2 * lo; ++i) pad[i] = hi - lo + i < L ? r[hi - lo + i] : T(0);
      conv_end_taps(pad + s0, o + hi + s0, e - s0, C, wk);
    }
    return;
  }
  auto scalar_ends = [&](int a, int b) {  // the taps inside the row only
    for (int j = a; j < b; ++j) {
      T s = 0;
      for (int k = 0; k < kWin; ++k) {
        int q = j + (k - kHalf) * C;
        if (q >= 0 && q < L) s = fused(w[k], r[q], s);
      }
      o[j] = s;
    }
  };
  scalar_ends(j0, std::min(j1, lo));
  if (hi > lo && std::min(j1, hi) > std::max(j0, lo))
    conv_taps(r - kHalf * C, o, std::max(j0, lo), std::min(j1, hi), C, wk);
  scalar_ends(std::max(j0, std::max(hi, lo)), j1);
}

template <typename T>
void conv_row(const T* r, T* o, int W, int C) {
  conv_row_range(r, o, W, C, 0, W * C);
}

// Vertical 11-tap pass for output row y of an H-row image whose horizontally filtered rows live in a ring of
// kWin rows (`ring(row)` returns the row's buffer): o = sum_k w[k] ring(y + k - 5) over rows inside [0, H).
template <typename T, class Ring>
void conv_col(Ring&& ring, int y, int H, int L, T* o) {
  const T* w = ssim_window<T>();
  const int k0 = std::max(0, kHalf - y), k1 = std::min(kWin, H + kHalf - y);
  if (k0 == 0 && k1 == kWin) {
    // Full window: the 11 rows summed in registers, one store per output.
    const T* rr[kWin];
    T wk[kWin];
    for (int k = 0; k < kWin; ++k) rr[k] = ring(y + k - kHalf), wk[k] = w[k];
#pragma omp simd
    for (int j = 0; j < L; ++j) {
      T acc = wk[0] * rr[0][j];
#pragma GCC unroll 11
      for (int k = 1; k < kWin; ++k) acc += wk[k] * rr[k][j];
      o[j] = acc;
    }
    return;
  }
  {
    const T* r = ring(y + k0 - kHalf);
    const T wk = w[k0];
#pragma omp simd
    for (int j = 0; j < L; ++j) o[j] = wk * r[j];
  }
  for (int k = k0 + 1; k < k1; ++k) {
    const T* r = ring(y + k - kHalf);
    const T wk = w[k];
#pragma omp simd
    for (int j = 0; j < L; ++j) o[j] += wk * r[j];
  }
}

// The SSIM terms of pixel j from the five moment rows (mu_x, mu_y, E[xx], E[yy], E[xy]); map = A1 A2 / (B1 B2).
template <typename T>
struct Terms {
  T A1, A2, B1, B2;
};
template <typename T>
inline Terms<T> ssim_terms(T* const* mom, int j, T C1, T C2) {
  const T mu1 = mom[0][j], mu2 = mom[1][j];
  const T s11 = mom[2][j] - mu1 * mu1, s22 = mom[3][j] - mu2 * mu2, s12 = mom[4][j] - mu1 * mu2;
  return {2 * mu1 * mu2 + C1, 2 * s12 + C2, mu1 * mu1 + mu2 * mu2 + C1, s11 + s22 + C2};
}

// Which values of a row each pass computes, as value indices (pixel column x C), for output columns [ox0, ox1):
// the gradient there [g0, g1), the moments, the map and the coefficients 5 pixels further [e0, e1) (what the
// gradient's vertical and horizontal passes read). y's support clipped to the image and to those: rows [r0, r1),
// the values [b0, b1) of a row where y may be non-zero and [a0, a1) where its filtered rows and moments may be
// (5 pixels more on each side); r0 = r1 for a null y.
struct Plan {
  int g0 = 0, g1 = 0, e0 = 0, e1 = 0;
  int r0 = 0, r1 = 0, a0 = 0, a1 = 0, b0 = 0, b1 = 0;
  Plan(const SsimSupport& s, bool has_y, int H, int W, int C, int ox0 = 0, int ox1 = 1 << 30) {
    ox0 = std::max(0, ox0), ox1 = std::min(W, ox1);
    if (ox0 >= ox1) return;
    g0 = ox0 * C, g1 = ox1 * C;
    e0 = std::max(0, ox0 - kHalf) * C, e1 = std::min(W, ox1 + kHalf) * C;
    const int x0 = std::max(0, s.x0), x1 = std::min(W, s.x1), y0 = std::max(0, s.y0), y1 = std::min(H, s.y1);
    if (!has_y || x0 >= x1 || y0 >= y1) return;
    b0 = std::max(g0, x0 * C), b1 = std::min(g1, x1 * C);
    a0 = std::max(e0, std::max(0, x0 - kHalf) * C), a1 = std::min(e1, std::min(W, x1 + kHalf) * C);
    if (a0 >= a1) return;  // (then b0 >= b1 too)
    b1 = std::max(b0, b1);
    r0 = y0, r1 = y1;
  }
  bool any() const { return r1 > r0; }
  bool rows(int r, int margin) const { return any() && r >= r0 - margin && r < r1 + margin; }
};

// SSIM of output rows [y0, y1) as a line-buffer pipeline, so every intermediate row stays in cache:
//   product rows (x, y, xx, yy, xy) -> horizontal pass -> ring P (11 rows)
//   moment row m (vertical pass over P rows m-5..m+5) -> map (summed into row_sum[m]) and, with a gradient,
//   the three backward coefficients -> horizontal pass -> coefficient row m -> out.done(m).
// `out` says where row m's map and coefficients go (ArrayRows: the image's [H, L] and [H, 3, L], shared by the
// bands; StreamRows: a ring of 11 rows, each gradient row made as soon as its coefficient rows are complete).
// x and y are read by row (xrow(r), yrow(r)). Product rows are computed for [y0 - 5, y1 + 5) (clipped), so a band needs
// nothing from its neighbours; every value is computed with the same arithmetic whatever the banding. Every pass
// computes only the values of a row the plan `sp` names: the moments, the map and the coefficients 5 pixels around the
// output columns, the coefficients' horizontal pass at the output columns; y's passes (its product rows, its three
// moments, the coefficient of E[xy]) only where they can be non-zero, everywhere else those values are 0, as the full
// passes over y's zeros give them. row_sum[m] sums the map over [e0, e1). kMap: the map's values are also stored
// (out.map_row). `g` is the gradient's normaliser 1 / count.
template <typename T, bool kMap, class XRow, class YRow, class Out>
void ssim_band(const XRow& xrow, const YRow& yrow, int H, int W, int C, int y0, int y1, const Plan& sp, Out& out,
               double* row_sum, T g, ScratchVector<T>& buf) {
  const int L = W * C;
  const T C1 = T(0.01 * 0.01), C2 = T(0.03 * 0.03);
  buf.resize(size_t(kWin) * 5 * L + size_t(8) * L);
  T* P = buf.data();                  // [11][5][L]
  T* tmp = P + size_t(kWin) * 5 * L;  // [8][L]: products, moments
  auto prow = [&](int row, int map) { return P + (size_t(row % kWin) * 5 + map) * L; };
  int next_p = std::max(0, y0 - kHalf);  // next product row to compute
  const int a0 = sp.a0, a1 = sp.a1, e0 = sp.e0, e1 = sp.e1;
  T* mom[5];
  for (int k = 0; k < 5; ++k) mom[k] = tmp + size_t(3 + k) * L;
  for (int k : {1, 3, 4}) std::fill(mom[k], mom[k] + L, T(0));  // y's moments outside [a0, a1): 0
  bool y_moments = false;                                       // mom[1, 3, 4] hold values in [a0, a1)
  for (int m = y0; m < y1; ++m) {
    for (; next_p <= std::min(H - 1, m + kHalf); ++next_p) {
      const T* xr = xrow(next_p);
      T *pxx = tmp, *pyy = tmp + L, *pxy = tmp + 2 * L;
      const int f0 = std::max(0, e0 - kHalf * C), f1 = std::min(L, e1 + kHalf * C);  // what outputs [e0, e1) read
#pragma omp simd
      for (int j = f0; j < f1; ++j) pxx[j] = xr[j] * xr[j];
      conv_row_range(xr, prow(next_p, 0), W, C, e0, e1);
      conv_row_range(pxx, prow(next_p, 2), W, C, e0, e1);
      if (sp.rows(next_p, 0)) {  // the outputs [a0, a1), which read the products 5 pixels further
        const T* yr = yrow(next_p);
        const int c0 = std::max(0, a0 - kHalf * C), c1 = std::min(L, a1 + kHalf * C);
#pragma omp simd
        for (int j = c0; j < c1; ++j) {
          pyy[j] = yr[j] * yr[j];
          pxy[j] = xr[j] * yr[j];
        }
        conv_row_range(yr, prow(next_p, 1), W, C, a0, a1);
        conv_row_range(pyy, prow(next_p, 3), W, C, a0, a1);
        conv_row_range(pxy, prow(next_p, 4), W, C, a0, a1);
      } else if (sp.rows(next_p, 2 * kHalf)) {  // a zero row that a moment row of y's reads
        for (int k : {1, 3, 4}) std::fill(prow(next_p, k) + a0, prow(next_p, k) + a1, T(0));
      }
    }
    for (int k : {0, 2}) conv_col<T>([&](int r) { return prow(r, k) + e0; }, m, H, e1 - e0, mom[k] + e0);
    if (sp.rows(m, kHalf)) {
      for (int k : {1, 3, 4}) conv_col<T>([&](int r) { return prow(r, k) + a0; }, m, H, a1 - a0, mom[k] + a0);
      y_moments = true;
    } else if (y_moments) {
      for (int k : {1, 3, 4}) std::fill(mom[k] + a0, mom[k] + a1, T(0));
      y_moments = false;
    }
    T* mrow = kMap ? out.map_row(m) : nullptr;
    T* coeff = out.coeff_row(m);
    if (!coeff) {
      double total = 0;
#pragma omp simd reduction(+ : total)
      for (int j = e0; j < e1; ++j) {
        const Terms<T> t = ssim_terms(mom, j, C1, C2);
        const T v = t.A1 * t.A2 * (T(1) / (t.B1 * t.B2));
        total += v;
        if constexpr (kMap) mrow[j] = v;
      }
      row_sum[m] = total;
      continue;
    }
    T *dmu = coeff, *dxx = coeff + L, *dxy = coeff + 2 * size_t(L);
    double total = 0;
#pragma omp simd reduction(+ : total)
    for (int j = e0; j < e1; ++j) {
      const Terms<T> t = ssim_terms(mom, j, C1, C2);
      const T mu1 = mom[0][j], mu2 = mom[1][j], A1 = t.A1, A2 = t.A2, B1 = t.B1, B2 = t.B2;
      const T inv = T(1) / (B1 * B2);
      const T map = A1 * A2 * inv;
      total += map;
      if constexpr (kMap) mrow[j] = map;
      // g d/dmu_x, g d/dE[xx], g d/dE[xy] (see the top of the file)
      dmu[j] = g * (2 * mu2 * (A2 - A1) * inv - map * (2 * mu1 / B1 - 2 * mu1 / B2));
      dxx[j] = -g * map / B2;
      dxy[j] = g * 2 * A1 * inv;
    }
    row_sum[m] = total;
    // Horizontal pass of the coefficients, in place through a scratch row. E[xy]'s multiplies y: it is needed
    // only inside y's support, whose outputs read the segment [a0, a1) alone.
    for (T* q : {dmu, dxx}) {  // the outputs [g0, g1) read [e0, e1)
      std::copy(q + e0, q + e1, tmp + e0);
      conv_row_range(tmp, q, W, C, sp.g0, sp.g1);
    }
    if (sp.rows(m, kHalf)) {  // the outputs [b0, b1) read [a0, a1)
      std::copy(dxy + a0, dxy + a1, tmp + a0);
      conv_row_range(tmp, dxy, W, C, sp.b0, sp.b1);
    }
    out.done(m);
  }
}

// Gradient row yy: the vertical pass over the horizontally filtered coefficient rows yy-5..yy+5 (coeff_row(r):
// row r's three [L] rows, complete), then dL/dx = v_mu + 2 x v_xx + y v_xy, the last term inside y's support only
// (y is 0 elsewhere). xr, yr: rows yy of x and y (yr read only inside the support); v: three [L] scratch rows.
template <typename T, class CoeffRow>
void ssim_grad_row(const T* xr, const T* yr, int H, int L, int yy, const Plan& sp, const CoeffRow& coeff_row, T* gr,
                   T* const* v) {
  const int b0 = sp.b0, b1 = sp.b1, g0 = sp.g0, g1 = sp.g1;
  const bool with_y = sp.rows(yy, 0);
  for (int k = 0; k < 2; ++k)
    conv_col<T>([&](int r) { return coeff_row(r) + size_t(k) * L + g0; }, yy, H, g1 - g0, v[k] + g0);
  if (with_y) conv_col<T>([&](int r) { return coeff_row(r) + 2 * size_t(L) + b0; }, yy, H, b1 - b0, v[2] + b0);
  auto with_y_term = [&](int j0, int j1) {
#pragma omp simd
    for (int j = j0; j < j1; ++j) gr[j] = v[0][j] + 2 * xr[j] * v[1][j] + yr[j] * v[2][j];
  };
  if (with_y && b0 == g0 && b1 == g1) {  // y anywhere in the row's outputs
    with_y_term(g0, g1);
    return;
  }
#pragma omp simd
  for (int j = g0; j < g1; ++j) gr[j] = v[0][j] + 2 * xr[j] * v[1][j];
  if (with_y) with_y_term(b0, b1);
}

// Where ssim_band puts row m's map (kMap) and coefficients, and what follows once they are complete.
// The whole image's: map [H, L], coeff [H, 3, L] (null: no gradient).
template <typename T>
struct ArrayRows {
  T *map, *coeff;
  int L;
  T* map_row(int m) const { return map + size_t(m) * L; }
  T* coeff_row(int m) const { return coeff ? coeff + size_t(m) * 3 * L : nullptr; }
  void done(int) const {}
};

// Streamed (ssim_rows_streamed): the map and coefficients of the last 11 rows in a ring; once row m's are
// complete, gradient row m - 5 (which reads coefficient rows m - 10 .. m) is computed and handed to the sink with
// its map row.
template <typename T, class XRow, class YRow, class Sink>
struct StreamRows {
  const XRow& xrow;
  const YRow& yrow;
  const Sink& sink;
  const Plan& sp;
  int H, L, y0, y1;
  T* ring;  // [11][4][L]: map, then the three coefficient rows
  T* v[3];  // [L] each: the gradient's vertical passes
  T* grad;  // [L] the gradient row
  T* map_row(int m) const { return ring + size_t(m % kWin) * 4 * L; }
  T* coeff_row(int m) const { return map_row(m) + L; }
  void emit(int yy) const {
    ssim_grad_row(
        xrow(yy), sp.rows(yy, 0) ? yrow(yy) : nullptr, H, L, yy, sp,
        [&](int r) { return static_cast<const T*>(coeff_row(r)); }, grad, v);
    sink(yy, static_cast<const T*>(grad), static_cast<const T*>(map_row(yy)));
  }
  void done(int m) const {
    if (m - kHalf >= y0 && m - kHalf < y1) emit(m - kHalf);
  }
};

}  // namespace

template <typename T>
const T* ssim_window() {
  static const Window<T> win;
  return win.w;
}

template <typename T>
T ssim(const T* x, const T* y, int H, int W, int C, T* grad_x, SsimWorkspace<T>& ws) {
  return ssim_map(x, y, H, W, C, grad_x, static_cast<T*>(nullptr), double(size_t(H) * W * C), ws);
}

template <typename T>
T ssim_map(const T* x, const T* y, int H, int W, int C, T* grad_x, T* map, double count, SsimWorkspace<T>& ws) {
  // Bands of rows, one per thread (one band when called inside a parallel region); per-row sums added in row
  // order, so the value and the gradient are bitwise independent of the thread count.
  // With a gradient: two phases, all bands' coefficient rows first, then the gradient rows, which read their
  // neighbours' coefficient rows instead of recomputing them (the one-pass bands recomputed 10 moment and 20
  // product rows each, 1.78x from one thread to two).
  ws.row_sum.assign(size_t(H), 0.0);
  const int bands = omp_in_parallel() ? 1 : std::max(1, std::min(omp_get_max_threads(), H / (2 * kWin)));
  if (ws.band.size() < size_t(bands)) ws.band.resize(bands);
  const int L = W * C;
  if (grad_x) ws.coeff.resize(size_t(H) * 3 * L);
  T* coeff = grad_x ? ws.coeff.data() : nullptr;
  const T g = T(1) / T(count);
  const Plan sp(SsimSupport{}, y != nullptr, H, W, C);
  const auto xrow = [&](int r) { return x + size_t(r) * L; };
  const auto yrow = [&](int r) { return y + size_t(r) * L; };
  ArrayRows<T> out{map, coeff, L};
#pragma omp parallel num_threads(bands) if (bands > 1)
  {
#pragma omp for schedule(static, 1)
    for (int b = 0; b < bands; ++b) {
      const int y0 = int(long(H) * b / bands), y1 = int(long(H) * (b + 1) / bands);
      if (map) ssim_band<T, true>(xrow, yrow, H, W, C, y0, y1, sp, out, ws.row_sum.data(), g, ws.band[b]);
      else ssim_band<T, false>(xrow, yrow, H, W, C, y0, y1, sp, out, ws.row_sum.data(), g, ws.band[b]);
    }
    if (grad_x) {
#pragma omp for schedule(static, 1)
      for (int b = 0; b < bands; ++b) {
        ScratchVector<T>& buf = ws.band[b];
        buf.resize(std::max(buf.size(), size_t(3) * L));
        T* v[3] = {buf.data(), buf.data() + L, buf.data() + 2 * size_t(L)};
        for (int r = int(long(H) * b / bands); r < int(long(H) * (b + 1) / bands); ++r)
          ssim_grad_row(
              xrow(r), y ? yrow(r) : nullptr, H, L, r, sp, [&](int m) { return out.coeff_row(m); },
              grad_x + size_t(r) * L, v);
      }
    }
  }
  double total = 0;
  for (int r = 0; r < H; ++r) total += ws.row_sum[r];
  return T(total / (double(H) * W * C));
}

template <typename T>
void ssim_rows_streamed(const SsimRow<T>& xrow, const SsimRow<T>& yrow, int H, int W, int C, int y0, int y1,
                        double count, SsimWorkspace<T>& ws, const SsimSink<T>& sink, SsimSupport ys, int x0, int x1) {
  y0 = std::max(0, y0);
  y1 = std::min(H, y1);
  if (y0 >= y1) return;
  const int L = W * C, m0 = std::max(0, y0 - kHalf), m1 = std::min(H, y1 + kHalf);
  ws.row_sum.assign(size_t(H), 0.0);
  if (ws.band.empty()) ws.band.resize(1);
  ws.coeff.resize(size_t(kWin) * 4 * L + 4 * size_t(L));  // the ring, v, the gradient row
  T* ring = ws.coeff.data();
  T* rest = ring + size_t(kWin) * 4 * L;
  const T g = T(1) / T(count);
  const Plan sp(ys, static_cast<bool>(yrow), H, W, C, x0, x1);
  StreamRows<T, SsimRow<T>, SsimRow<T>, SsimSink<T>> out{
      xrow, yrow, sink, sp, H, L, y0, y1, ring, {rest, rest + L, rest + 2 * size_t(L)}, rest + 3 * size_t(L)};
  ssim_band<T, true>(xrow, yrow, H, W, C, m0, m1, sp, out, ws.row_sum.data(), g, ws.band[0]);
  for (int yy = std::max(y0, m1 - kHalf); yy < y1; ++yy) out.emit(yy);  // the rows within 5 of the image's end
}

template <typename T>
void ssim_map_rows(const T* x, const T* y, int H, int W, int C, int y0, int y1, T* grad_x, T* map, double count,
                   SsimWorkspace<T>& ws, SsimSupport ys, int x0, int x1) {
  const Plan sp(ys, y != nullptr, H, W, C, x0, x1);  // (for the columns the sink's rows hold)
  const size_t L = size_t(W) * C;
  ssim_rows_streamed<T>([&](int r) { return x + size_t(r) * L; },
                        y ? SsimRow<T>([&](int r) { return y + size_t(r) * L; }) : SsimRow<T>(), H, W, C, y0, y1, count,
                        ws,
                        [&](int r, const T* gr, const T* mr) {
                          std::copy(gr + sp.g0, gr + sp.g1, grad_x + r * L + sp.g0);
                          std::copy(mr + sp.e0, mr + sp.e1, map + r * L + sp.e0);
                        },
                        ys, x0, x1);
}

template float ssim<float>(const float*, const float*, int, int, int, float*, SsimWorkspace<float>&);
template float ssim_map<float>(const float*, const float*, int, int, int, float*, float*, double,
                               SsimWorkspace<float>&);
template double ssim_map<double>(const double*, const double*, int, int, int, double*, double*, double,
                                 SsimWorkspace<double>&);
template void ssim_map_rows<float>(const float*, const float*, int, int, int, int, int, float*, float*, double,
                                   SsimWorkspace<float>&, SsimSupport, int, int);
template void ssim_map_rows<double>(const double*, const double*, int, int, int, int, int, double*, double*, double,
                                    SsimWorkspace<double>&, SsimSupport, int, int);
template void ssim_rows_streamed<float>(const SsimRow<float>&, const SsimRow<float>&, int, int, int, int, int, double,
                                        SsimWorkspace<float>&, const SsimSink<float>&, SsimSupport, int, int);
template void ssim_rows_streamed<double>(const SsimRow<double>&, const SsimRow<double>&, int, int, int, int, int,
                                         double, SsimWorkspace<double>&, const SsimSink<double>&, SsimSupport, int,
                                         int);
template double ssim<double>(const double*, const double*, int, int, int, double*, SsimWorkspace<double>&);
template const float* ssim_window<float>();
template const double* ssim_window<double>();

}  // namespace hgs::train
