// Tiny SIMD layer for the rasterizer: fixed 8-lane packs built on GCC vector extensions, so the same template
// code runs as float x 8 (one AVX2 register; the production path) and double x 8 (the exact test path).
// The kernels that use it are compiled twice (render/raster_isa.h): for the portable x86-64-v3 baseline and with
// AVX-512 (the same 8-lane packs with 32 vector registers and mask registers). Each compilation keeps these
// helpers in its own inline namespace (avx2 / avx512, HGS_RASTER_NS). They are compiled for the baseline and
// inlined into the AVX-512 kernels (raster_isa_begin.h), so no out-of-line copy ever holds AVX-512 code.
// Masks are integer vectors of the same lane size (-1 = true), `m ? a : b` selects lane-wise.
// vexp(float pack) is a Cephes-style polynomial exp (about 1 ulp on the rasterizer's range, x <= 0);
// vexp(double pack) calls std::exp per lane so double instantiations are exact references.
#pragma once
#include <cmath>
#include <cstdint>
#include <cstring>
#if defined(__AVX2__)
#include <immintrin.h>
#endif

// The namespace of the kernels compiled with these helpers (hgs::render::avx2 / avx512, raster_isa.h).
#if defined(HGS_RASTER_AVX512)
#define HGS_RASTER_NS avx512
#else
#define HGS_RASTER_NS avx2
#endif

// Passing 64-byte double packs by value only changes the ABI of non-inlined helpers; silence GCC's note.
#pragma GCC diagnostic ignored "-Wpsabi"

namespace hgs::render::simd {
inline namespace HGS_RASTER_NS {

constexpr int kLanes = 8;  // pixels per batch (half a 16-pixel tile row)

template <class T>
struct PackTraits;
template <>
struct PackTraits<float> {
  typedef float P __attribute__((vector_size(32)));
  typedef int32_t M __attribute__((vector_size(32)));
};
template <>
struct PackTraits<double> {
  typedef double P __attribute__((vector_size(64)));
  typedef int64_t M __attribute__((vector_size(64)));
};
template <class T>
using Pack = typename PackTraits<T>::P;
template <class T>
using Mask = typename PackTraits<T>::M;

template <class T>
inline __attribute__((always_inline)) Pack<T> splat(T v) {
  return Pack<T>{} + v;
}

template <class T>
inline __attribute__((always_inline)) Pack<T> iota_pack() {
  Pack<T> p;
  for (int l = 0; l < kLanes; ++l) p[l] = T(l);
  return p;
}

// a * b + c with one rounding, whatever the compiler would contract: GCC fuses a * b + c into an FMA only when
// both sit in one basic block after its code motion, which the surrounding code can change (the backward's folded
// and list paths must round alike).
inline __attribute__((always_inline)) Pack<float> fmadd(Pack<float> a, Pack<float> b, Pack<float> c) {
#if defined(__FMA__)
  return (Pack<float>)_mm256_fmadd_ps((__m256)a, (__m256)b, (__m256)c);
#else
  Pack<float> r;
  for (int l = 0; l < kLanes; ++l) r[l] = std::fma(a[l], b[l], c[l]);
  return r;
#endif
}
inline __attribute__((always_inline)) Pack<double> fmadd(Pack<double> a, Pack<double> b, Pack<double> c) {
  Pack<double> r;
  for (int l = 0; l < kLanes; ++l) r[l] = std::fma(a[l], b[l], c[l]);
  return r;
}

template <class T>
inline __attribute__((always_inline)) Pack<T> vmin(Pack<T> a, Pack<T> b) {
  return a < b ? a : b;
}

// True when any lane of the mask is set.
inline __attribute__((always_inline)) bool any(Mask<float> m) {
#if defined(__AVX2__)
  __m256i v;
  std::memcpy(&v, &m, sizeof(v));
  return !_mm256_testz_si256(v, v);
#else
  int32_t r = 0;
  for (int l = 0; l < kLanes; ++l) r |= m[l];
  return r != 0;
#endif
}
inline __attribute__((always_inline)) bool any(Mask<double> m) {
  int64_t r = 0;
  for (int l = 0; l < kLanes; ++l) r |= m[l];
  return r != 0;
}

// Lane sum in a fixed order (deterministic).
template <class T>
inline __attribute__((always_inline)) T hsum(Pack<T> p) {
  T a = (p[0] + p[4]) + (p[2] + p[6]);
  T b = (p[1] + p[5]) + (p[3] + p[7]);
  return a + b;
}

// The lane sums of 8 packs at once: lane j of the result is hsum(v[j]), bitwise (each addition adds the same two
// operands as hsum's tree; float addition is commutative), in three transposing levels instead of 8 reductions.
inline __attribute__((always_inline)) Pack<float> hsum8(const Pack<float>* v) {
#if defined(__AVX2__)
  __m256 t[4];  // level 1: [v_2i[l] + v_2i[l + 4] | v_2i+1[l] + v_2i+1[l + 4]], l = 0..3
  for (int i = 0; i < 4; ++i) {
    const __m256 a = (__m256)v[2 * i], b = (__m256)v[2 * i + 1];
    t[i] = _mm256_add_ps(_mm256_permute2f128_ps(a, b, 0x20), _mm256_permute2f128_ps(a, b, 0x31));
  }
  // level 2: lanes (0, 2) and (1, 3) of each half: [a0, b0, a2, b2 | a1, b1, a3, b3] and the same for 4..7
  const __m256 x = _mm256_add_ps(_mm256_shuffle_ps(t[0], t[1], 0x44), _mm256_shuffle_ps(t[0], t[1], 0xEE));
  const __m256 y = _mm256_add_ps(_mm256_shuffle_ps(t[2], t[3], 0x44), _mm256_shuffle_ps(t[2], t[3], 0xEE));
  // level 3: a + b: [h0, h2, h4, h6 | h1, h3, h5, h7], then into order
  const __m256 h = _mm256_add_ps(_mm256_shuffle_ps(x, y, 0x88), _mm256_shuffle_ps(x, y, 0xDD));
  return (Pack<float>)_mm256_permutevar8x32_ps(h, _mm256_setr_epi32(0, 4, 1, 5, 2, 6, 3, 7));
#else
  Pack<float> r;
  for (int j = 0; j < kLanes; ++j) r[j] = hsum<float>(v[j]);
  return r;
#endif
}
inline __attribute__((always_inline)) Pack<double> hsum8(const Pack<double>* v) {
  Pack<double> r;
  for (int j = 0; j < kLanes; ++j) r[j] = hsum<double>(v[j]);
  return r;
}

// exp for x <= ~88: range-reduced polynomial (Cephes expf coefficients); x < -87 flushes to ~0.
inline __attribute__((always_inline)) Pack<float> vexp(Pack<float> x) {
  typedef Pack<float> P;
  typedef Mask<float> M;
  x = x < -87.0f ? splat(-87.0f) : x;
  x = x > 88.0f ? splat(88.0f) : x;
  P fx = x * 1.44269504088896341f;
  // round to nearest via the 1.5 * 2^23 trick (|fx| < 2^22 here)
  const float magic = 12582912.0f;
  P n = (fx + magic) - magic;
  P r = x - n * 0.693359375f;
  r = r - n * -2.12194440e-4f;
  P r2 = r * r;
  P p = splat(1.9875691500e-4f);
  p = p * r + 1.3981999507e-3f;
  p = p * r + 8.3334519073e-3f;
  p = p * r + 4.1665795894e-2f;
  p = p * r + 1.6666665459e-1f;
  p = p * r + 5.0000001201e-1f;
  p = p * r2 + r + 1.0f;
  M e = __builtin_convertvector(n, M);
  e = (e + 127) << 23;
  P scale;
  std::memcpy(&scale, &e, sizeof(scale));
  return p * scale;
}
inline __attribute__((always_inline)) Pack<double> vexp(Pack<double> x) {
  Pack<double> r;
  for (int l = 0; l < kLanes; ++l) r[l] = std::exp(x[l]);
  return r;
}

// 1 / x: for float the hardware estimate refined by one Newton step (~1e-7 relative error, the same as the
// division to within an ulp or two); for double an exact division.
inline __attribute__((always_inline)) Pack<float> vrecip(Pack<float> x) {
#if defined(__AVX__)
  Pack<float> r = (Pack<float>)_mm256_rcp_ps((__m256)x);
  return r * (2.0f - x * r);
#else
  return 1.0f / x;
#endif
}
inline __attribute__((always_inline)) Pack<double> vrecip(Pack<double> x) { return 1.0 / x; }

}  // namespace HGS_RASTER_NS
}  // namespace hgs::render::simd
