// Array drivers of the spherical-harmonics colour (per-Gaussian math in sh.h), parallel over chunks of Gaussians.
//
// float runs 8 Gaussians at a time: each chunk's active Gaussians are listed, and every group of 8 has its SH
// rows, means and upstream colours transposed into lanes (8x8 block transposes of the [N, stride, 3] rows), goes
// through sh.h's own templates instantiated on G8 (one float lane per Gaussian: the same IEEE operations in the
// same order as T = float; this file is compiled with -ffp-contract=off, so results are bitwise the scalar ones)
// and is transposed back. The last < 8 active Gaussians of a chunk take the scalar templates. double (the
// finite-difference tests) is scalar throughout.
#include "render/sh.h"

#include <algorithm>
#include <type_traits>

#include "core/parallel.h"
#if defined(__AVX__)
#include <immintrin.h>
#endif

namespace hgs::render {
namespace {

typedef float F8 __attribute__((vector_size(32)));
constexpr int kLanes = 8;
constexpr int kChunk = 256;  // Gaussians per OpenMP work item

// One float per Gaussian of a group of 8, with the arithmetic sh.h's templates use, lane-wise.
struct G8 {
  F8 v;
  G8() = default;
  G8(F8 x) : v(x) {}
  template <class S>
  requires std::is_arithmetic_v<S> G8(S s) {  // broadcast, rounded to float first like T(s) for T = float
    const float f = float(s);
    v = F8{f, f, f, f, f, f, f, f};
  }
  friend G8 operator+(G8 a, G8 b) { return a.v + b.v; }
  friend G8 operator-(G8 a, G8 b) { return a.v - b.v; }
  friend G8 operator*(G8 a, G8 b) { return a.v * b.v; }
  friend G8 operator/(G8 a, G8 b) { return a.v / b.v; }
  friend G8 operator-(G8 a) { return -a.v; }
  G8& operator+=(G8 b) {
    v += b.v;
    return *this;
  }
  friend G8 sh_if_positive(G8 c, G8 a, G8 b) { return c.v > 0.0f ? a.v : b.v; }
  friend G8 sh_sqrt(G8 x) {  // correctly rounded, as std::sqrt
#if defined(__AVX__)
    return F8(_mm256_sqrt_ps(__m256(x.v)));
#else
    for (int l = 0; l < kLanes; ++l) x.v[l] = std::sqrt(x.v[l]);
    return x;
#endif
  }
};

#if defined(__AVX__)
// 4x4 transposes within each 128-bit half: a..d hold rows 0..3 (low half) and 4..7 (high half) of 4 columns and
// come out as columns 0..3 of those rows, or back (it is its own inverse).
inline void transpose4_halves(__m256& a, __m256& b, __m256& c, __m256& d) {
  const __m256 t0 = _mm256_unpacklo_ps(a, b), t1 = _mm256_unpackhi_ps(a, b);
  const __m256 t2 = _mm256_unpacklo_ps(c, d), t3 = _mm256_unpackhi_ps(c, d);
  a = _mm256_shuffle_ps(t0, t2, 0x44), b = _mm256_shuffle_ps(t0, t2, 0xEE);
  c = _mm256_shuffle_ps(t1, t3, 0x44), d = _mm256_shuffle_ps(t1, t3, 0xEE);
}
#endif

// Lane l of out[j] = rows[l][j] for j < cols.
void load_lanes(const float* const* rows,  // [8] rows of at least cols floats
                int cols,
                G8* out) {  // [cols]
  int j = 0;
#if defined(__AVX__)
  for (; j + 8 <= cols; j += 8) {
    __m256 r[8];  // r[q] / r[4 + q]: columns j..j+3 / j+4..j+7 of rows q (low half) and q + 4 (high half)
    for (int q = 0; q < 4; ++q)
      for (int h = 0; h < 2; ++h)
        r[4 * h + q] = _mm256_insertf128_ps(_mm256_castps128_ps256(_mm_loadu_ps(rows[q] + j + 4 * h)),
                                            _mm_loadu_ps(rows[q + 4] + j + 4 * h), 1);
    transpose4_halves(r[0], r[1], r[2], r[3]);
    transpose4_halves(r[4], r[5], r[6], r[7]);
    for (int t = 0; t < 8; ++t) out[j + t].v = F8(r[t]);
  }
#endif
  for (; j < cols; ++j)
    for (int l = 0; l < kLanes; ++l) out[j].v[l] = rows[l][j];
}

// The inverse: rows[l][j] = lane l of in[j] for j < cols.
void store_lanes(const G8* in,  // [cols]
                 int cols,
                 float* const* rows) {  // [8] rows of at least cols floats
  int j = 0;
#if defined(__AVX__)
  for (; j + 8 <= cols; j += 8) {
    __m256 r[8];
    for (int t = 0; t < 8; ++t) r[t] = __m256(in[j + t].v);
    transpose4_halves(r[0], r[1], r[2], r[3]);
    transpose4_halves(r[4], r[5], r[6], r[7]);
    for (int q = 0; q < 4; ++q)
      for (int h = 0; h < 2; ++h) {
        _mm_storeu_ps(rows[q] + j + 4 * h, _mm256_castps256_ps128(r[4 * h + q]));
        _mm_storeu_ps(rows[q + 4] + j + 4 * h, _mm256_extractf128_ps(r[4 * h + q], 1));
      }
  }
#endif
  for (; j < cols; ++j)
    for (int l = 0; l < kLanes; ++l) rows[l][j] = in[j].v[l];
}

// Row pointers base + idx[l] * width for the 8 Gaussians idx [8].
template <class P>
inline void row_ptrs(P* base, size_t width, const int* idx, P** rows) {
  for (int l = 0; l < kLanes; ++l) rows[l] = base + size_t(idx[l]) * width;
}

// Over chunks of kChunk Gaussians in parallel: zero(i) for each inactive Gaussian, group(idx [8]) for each group of
// 8 active ones (ascending indices), one(i) for the active ones left over. The chunks go to the threads on demand
// (demand_chunk): the active (visible) Gaussians cluster by index once densification has appended its clones, and
// a static split left threads idle (the tabletop after densification, 16 threads simulated: 1.5-1.9x the balanced
// time; docs/performance.md, session sixteen).
template <class Zero, class Group, class One>
void each_active(int n, const int* active, Zero zero, Group group, One one) {
  const int chunks = (n + kChunk - 1) / kChunk;
#pragma omp parallel for schedule(dynamic, demand_chunk(chunks, 1))
  for (int ch = 0; ch < chunks; ++ch) {
    int idx[kChunk], m = 0;
    for (int i = ch * kChunk, end = std::min(n, i + kChunk); i < end; ++i)
      if (!active || active[i]) idx[m++] = i;
      else zero(i);
    int j = 0;
    for (; j + kLanes <= m; j += kLanes) group(idx + j);
    for (; j < m; ++j) one(idx[j]);
  }
}

// Lanes of the view directions mean - campos of the 8 Gaussians idx [8].
inline void load_dirs(const float* mean, const float* campos, const int* idx, G8* dir) {
  const float* rows[kLanes];
  row_ptrs(mean, 3, idx, rows);
  load_lanes(rows, 3, dir);
  for (int j = 0; j < 3; ++j) dir[j] = dir[j] - campos[j];
}

}  // namespace

template <class T>
void sh_forward(int n, int degree, int stride,
                const T* sh,        // [N, stride, 3]
                const T* mean,      // [N, 3]
                const T* campos,    // [3]
                const int* active,  // [N] or null
                T* colors) {        // [N, 3] out
  const size_t row = size_t(stride) * 3;
  auto one = [&](int i) {
    const T dir[3] = {mean[3 * i] - campos[0], mean[3 * i + 1] - campos[1], mean[3 * i + 2] - campos[2]};
    sh_eval_one(degree, sh + i * row, dir, colors + 3 * i);
  };
  auto group = [&](const int* idx) {
    if constexpr (std::is_same_v<T, float>) {
      const float* rows[kLanes];
      float* out[kLanes];
      G8 s[kMaxShCoeffs * 3], dir[3], col[3];
      row_ptrs(sh, row, idx, rows);
      load_lanes(rows, 3 * sh_num_coeffs(degree), s);
      load_dirs(mean, campos, idx, dir);
      sh_eval_one(degree, s, dir, col);
      row_ptrs(colors, 3, idx, out);
      store_lanes(col, 3, out);
    } else {
      for (int l = 0; l < kLanes; ++l) one(idx[l]);
    }
  };
  auto zero = [&](int i) { colors[3 * i] = colors[3 * i + 1] = colors[3 * i + 2] = 0; };
  each_active(n, active, zero, group, one);
}

template <class T>
void sh_backward(int n, int degree, int stride,
                 const T* sh,        // [N, stride, 3]
                 const T* mean,      // [N, 3]
                 const T* campos,    // [3]
                 const int* active,  // [N] or null
                 const T* dcolors,   // [N, 3]
                 T* dsh,             // [N, stride, 3] out
                 T* dmean) {         // [N, 3] accumulated, or null
  const int K = sh_num_coeffs(degree);
  const size_t row = size_t(stride) * 3;
  auto one = [&](int i) {
    T* d = dsh + i * row;
    std::fill(d + 3 * K, d + row, T(0));
    const T dir[3] = {mean[3 * i] - campos[0], mean[3 * i + 1] - campos[1], mean[3 * i + 2] - campos[2]};
    T ddir[3] = {0, 0, 0};
    sh_backward_one(degree, sh + i * row, dir, dcolors + 3 * i, d, ddir);
    if (dmean)
      for (int j = 0; j < 3; ++j) dmean[3 * i + j] += ddir[j];
  };
  auto group = [&](const int* idx) {
    if constexpr (std::is_same_v<T, float>) {
      const float* in[kLanes];
      float* out[kLanes];
      G8 s[kMaxShCoeffs * 3], ds[kMaxShCoeffs * 3], dir[3], dcol[3], ddir[3] = {0, 0, 0}, dm[3];
      row_ptrs(sh, row, idx, in);
      load_lanes(in, 3 * K, s);
      load_dirs(mean, campos, idx, dir);
      row_ptrs(dcolors, 3, idx, in);
      load_lanes(in, 3, dcol);
      sh_backward_one(degree, s, dir, dcol, ds, ddir);
      row_ptrs(dsh, row, idx, out);
      store_lanes(ds, 3 * K, out);
      for (int l = 0; l < kLanes; ++l) std::fill(out[l] + 3 * K, out[l] + row, 0.0f);
      if (dmean) {
        row_ptrs(dmean, 3, idx, out);
        load_lanes(out, 3, dm);
        for (int j = 0; j < 3; ++j) dm[j] += ddir[j];
        store_lanes(dm, 3, out);
      }
    } else {
      for (int l = 0; l < kLanes; ++l) one(idx[l]);
    }
  };
  auto zero = [&](int i) { std::fill(dsh + i * row, dsh + (i + 1) * row, T(0)); };
  each_active(n, active, zero, group, one);
}

template void sh_forward<float>(int, int, int, const float*, const float*, const float*, const int*, float*);
template void sh_forward<double>(int, int, int, const double*, const double*, const double*, const int*, double*);
template void sh_backward<float>(int, int, int, const float*, const float*, const float*, const int*, const float*,
                                 float*, float*);
template void sh_backward<double>(int, int, int, const double*, const double*, const double*, const int*, const double*,
                                  double*, double*);

}  // namespace hgs::render
