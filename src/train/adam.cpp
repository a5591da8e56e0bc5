// Adam update loops. Parameters whose columns share one learning rate are updated as a flat array (SIMD
// friendly); others (SH: DC vs higher coefficients) row by row. Row updates with bfloat16 moments (the hybrid
// method's f_n) run 16 columns per instruction where the CPU has AVX-512, 8 otherwise (the same operations, so the
// same bits), then one column at a time (tests/train/test_adam_densify.cpp holds all three to the element rule).
#include "train/adam.h"

#include <immintrin.h>

#include <algorithm>
#include <atomic>
#include <cmath>

#include "core/error.h"
#include "core/half.h"
#include "model/gaussian_model.h"

namespace hgs::train {

AdamParam& Adam::add(const std::string& name, int dim, int n, float lr, bool bf16) {
  if (find(name)) fail("adam: parameter '{}' added twice", name);
  AdamParam p;
  p.name = name;
  p.dim = dim;
  p.bf16 = bf16;
  p.set_lr(lr);
  if (bf16) {
    p.m16.assign(size_t(n) * dim, 0);
    p.v16.assign(size_t(n) * dim, 0);
  } else {
    p.m.assign(size_t(n) * dim, 0.f);
    p.v.assign(size_t(n) * dim, 0.f);
  }
  params.push_back(std::move(p));
  return params.back();
}

AdamParam& Adam::add_array(const std::string& name, int dim, int rows, float lr, float eps) {
  AdamParam& p = add(name, dim, rows, lr);
  p.scope = ParamScope::Array;
  p.eps = eps;
  return p;
}

AdamParam* Adam::find(const std::string& name) {
  for (auto& p : params)
    if (p.name == name) return &p;
  return nullptr;
}

const AdamParam* Adam::find(const std::string& name) const {
  for (auto& p : params)
    if (p.name == name) return &p;
  return nullptr;
}

AdamParam& Adam::get(const std::string& name) {
  AdamParam* p = find(name);
  if (!p) fail("adam: no parameter '{}'", name);
  return *p;
}

void Adam::update(AdamParam& p, float* value, const float* grad, int n) const {
  const size_t total = size_t(n) * p.dim;
  if (p.bf16) fail("adam: parameter '{}' has bfloat16 moments; update it with update_rows", p.name);
  if (p.m.size() != total) fail("adam: parameter '{}' has moments for {} values, got {}", p.name, p.m.size(), total);
  const double t = double(++p.step);
  const float bc1 = float(1.0 - std::pow(double(beta1), t));
  const float inv_sqrt_bc2 = float(1.0 / std::sqrt(1.0 - std::pow(double(beta2), t)));
  const float b1 = beta1, b2 = beta2, e = p.eps;
  float* m = p.m.data();
  float* v = p.v.data();
  bool uniform = std::all_of(p.lr.begin(), p.lr.end(), [&](float l) { return l == p.lr[0]; });
  long bad = 0;
  if (uniform) {
    const float step = p.lr[0] * lr_scale / bc1;
#pragma omp parallel for simd schedule(static) reduction(+ : bad)
    for (size_t i = 0; i < total; ++i) {
      float g = grad[i];
      bad += nonfinite_bit(g);
      float mi = b1 * m[i] + (1 - b1) * g;
      float vi = b2 * v[i] + (1 - b2) * g * g;
      m[i] = mi;
      v[i] = vi;
      value[i] -= step * mi / (std::sqrt(vi) * inv_sqrt_bc2 + e);
    }
  } else {
    const int d = p.dim;
    float steps[256];
    if (d > 256) fail("adam: parameter '{}' has {} columns with different rates (max 256)", p.name, d);
    for (int c = 0; c < d; ++c) steps[c] = p.lr[c] * lr_scale / bc1;
#pragma omp parallel for schedule(static) reduction(+ : bad)
    for (long r = 0; r < n; ++r) {
      const size_t o = size_t(r) * d;
#pragma omp simd reduction(+ : bad)
      for (int c = 0; c < d; ++c) {
        float g = grad[o + c];
        bad += nonfinite_bit(g);
        float mi = b1 * m[o + c] + (1 - b1) * g;
        float vi = b2 * v[o + c] + (1 - b2) * g * g;
        m[o + c] = mi;
        v[o + c] = vi;
        value[o + c] -= steps[c] * mi / (std::sqrt(vi) * inv_sqrt_bc2 + e);
      }
    }
  }
  p.nonfinite += bad;
}

void Adam::check_rows(const AdamParam& p, int n) const {
  if (p.rows() != size_t(n)) fail("adam: parameter '{}' has moments for {} rows, got {}", p.name, p.rows(), n);
  if (p.dim > kMaxRowUpdateDim)
    fail("adam: parameter '{}' is {} wide (row updates take at most {})", p.name, p.dim, kMaxRowUpdateDim);
}

namespace {

// Parameter values stored as float32 (X = float) or IEEE half (X = uint16_t, written back with stochastic
// rounding so that steps below half a unit are not lost: unbiased, like the bfloat16 moments).
inline float load_x(const float* x, int c) { return x[c]; }
inline float load_x(const uint16_t* x, int c) { return half_to_float(x[c]); }
inline void store_x(float* x, int c, float v, uint32_t) { x[c] = v; }
inline void store_x(uint16_t* x, int c, float v, uint32_t r) { x[c] = float_to_half_stochastic(v, r); }
inline uint32_t x_bits(uint32_t r) { return (r * 0x9E3779B1u) >> 19; }  // 13 bits decorrelated from m's and v's

#if defined(__AVX2__)
inline __m256 load_x8(const float* x) { return _mm256_loadu_ps(x); }
inline __m256 load_x8(const uint16_t* x) {
  return _mm256_cvtph_ps(_mm_loadu_si128(reinterpret_cast<const __m128i*>(x)));
}
inline void store_x8(float* x, __m256 v, __m256i) { _mm256_storeu_ps(x, v); }
inline void store_x8(uint16_t* x, __m256 v, __m256i r) {
  const __m256i bits = _mm256_srli_epi32(_mm256_mullo_epi32(r, _mm256_set1_epi32(int(0x9E3779B1u))), 19);
  const __m256 j = _mm256_castsi256_ps(_mm256_add_epi32(_mm256_castps_si256(v), bits));
  _mm_storeu_si128(reinterpret_cast<__m128i*>(x), _mm256_cvtps_ph(j, _MM_FROUND_TO_ZERO | _MM_FROUND_NO_EXC));
}
#endif

#if defined(__GNUC__) && !defined(__clang__) && defined(__AVX2__)
#define HGS_ADAM_AVX512 1
// The bfloat16-moment loop below, 16 columns per instruction with AVX-512 (chosen at run time when the CPU has
// it): the same operations lane for lane as the 8-wide loop (the lane seeds, the hash, the roundings), so the same
// bits; only whole blocks of 16 columns. Returns the first column it did not update. (Its helpers are the 8-wide
// ones at twice the width: the intrinsics differ by type, so they are written out twice.)
#pragma GCC push_options
#pragma GCC target("avx512f,avx512bw,avx512vl,avx512dq")
// GCC 12's AVX-512 conversion intrinsics start from a self-initialised "undefined" vector, which
// -Wmaybe-uninitialized reports once inlined (GCC bug 105593, fixed in GCC 13).
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wmaybe-uninitialized"
inline __m512 load_x16(const float* x) { return _mm512_loadu_ps(x); }
inline __m512 load_x16(const uint16_t* x) {
  return _mm512_cvtph_ps(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(x)));
}
inline void store_x16(float* x, __m512 v, __m512i) { _mm512_storeu_ps(x, v); }
inline void store_x16(uint16_t* x, __m512 v, __m512i r) {
  const __m512i bits = _mm512_srli_epi32(_mm512_mullo_epi32(r, _mm512_set1_epi32(int(0x9E3779B1u))), 19);
  const __m512 j = _mm512_castsi512_ps(_mm512_add_epi32(_mm512_castps_si512(v), bits));
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(x), _mm512_cvtps_ph(j, _MM_FROUND_TO_ZERO | _MM_FROUND_NO_EXC));
}

template <class X>
int adam_bf16_avx512(int d, X* x, const float* g, uint16_t* m, uint16_t* v, float b1, float b2, float e, float step,
                     float inv_sqrt_bc2, uint32_t base) {
  const __m512 vb1 = _mm512_set1_ps(b1), vb1c = _mm512_set1_ps(1 - b1), vb2 = _mm512_set1_ps(b2),
               vb2c = _mm512_set1_ps(1 - b2), vstep = _mm512_set1_ps(step), vbc2 = _mm512_set1_ps(inv_sqrt_bc2),
               veps = _mm512_set1_ps(e);
  const __m512i lane = _mm512_mullo_epi32(_mm512_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),
                                          _mm512_set1_epi32(int(0x9E3779B9u)));
  const __m512i low16 = _mm512_set1_epi32(0xFFFF);
  int c = 0;
  for (; c + 16 <= d; c += 16) {
    const __m512 mf = _mm512_castsi512_ps(
        _mm512_slli_epi32(_mm512_cvtepu16_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(m + c))), 16));
    const __m512 vf = _mm512_castsi512_ps(
        _mm512_slli_epi32(_mm512_cvtepu16_epi32(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(v + c))), 16));
    const __m512 g16 = _mm512_loadu_ps(g + c);
    const __m512 mi = _mm512_fmadd_ps(vb1, mf, _mm512_mul_ps(vb1c, g16));
    const __m512 vi = _mm512_fmadd_ps(vb2, vf, _mm512_mul_ps(vb2c, _mm512_mul_ps(g16, g16)));
    __m512i r = _mm512_add_epi32(_mm512_set1_epi32(int(base + uint32_t(c) * 0x9E3779B9u)), lane);
    r = _mm512_xor_si512(r, _mm512_srli_epi32(r, 16));
    r = _mm512_mullo_epi32(r, _mm512_set1_epi32(int(0x85EBCA6Bu)));
    r = _mm512_xor_si512(r, _mm512_srli_epi32(r, 13));
    r = _mm512_mullo_epi32(r, _mm512_set1_epi32(int(0xC2B2AE35u)));
    r = _mm512_xor_si512(r, _mm512_srli_epi32(r, 16));
    const __m512i mo = _mm512_add_epi32(_mm512_castps_si512(mi), _mm512_and_si512(r, low16));
    const __m512i vo = _mm512_add_epi32(_mm512_castps_si512(vi), _mm512_srli_epi32(r, 16));
    const __m512 den = _mm512_fmadd_ps(_mm512_sqrt_ps(vi), vbc2, veps);
    store_x16(x + c, _mm512_sub_ps(load_x16(x + c), _mm512_div_ps(_mm512_mul_ps(vstep, mi), den)), r);
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(m + c), _mm512_cvtepi32_epi16(_mm512_srli_epi32(mo, 16)));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(v + c), _mm512_cvtepi32_epi16(_mm512_srli_epi32(vo, 16)));
  }
  return c;
}
#pragma GCC diagnostic pop
#pragma GCC pop_options

bool adam_avx512_default() {
  __builtin_cpu_init();
  return __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512bw") &&
         __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512dq");
}
#endif

std::atomic<bool>& adam_avx512_flag() {
#ifdef HGS_ADAM_AVX512
  static std::atomic<bool> on{adam_avx512_default()};
#else
  static std::atomic<bool> on{false};
#endif
  return on;
}

template <class X>
void adam_row(const AdamParam& p, X* x, const float* g, float* m32, float* v32, uint16_t* m, uint16_t* v, float b1,
              float b2, float e, float step, float inv_sqrt_bc2, uint32_t base) {
  const int d = p.dim;
  if (m32) {
#pragma omp simd
    for (int c = 0; c < d; ++c) {
      const float mi = b1 * m32[c] + (1 - b1) * g[c];
      const float vi = b2 * v32[c] + (1 - b2) * g[c] * g[c];
      m32[c] = mi;
      v32[c] = vi;
      store_x(x, c, load_x(x, c) - step * mi / (std::sqrt(vi) * inv_sqrt_bc2 + e),
              x_bits(hash32(base + uint32_t(c) * 0x9E3779B9u)));
    }
    return;
  }
  // bfloat16 moments. Random bits: a hash of (element, step); the low half rounds m, the high half v.
  int c = 0;
#ifdef HGS_ADAM_AVX512
  if (adam_avx512_flag().load(std::memory_order_relaxed))
    c = adam_bf16_avx512(d, x, g, m, v, b1, b2, e, step, inv_sqrt_bc2, base);
#endif
#if defined(__AVX2__)
  // The same arithmetic 8 columns at a time (GCC does not vectorise the bit casts of the scalar loop).
  const __m256 vb1 = _mm256_set1_ps(b1), vb1c = _mm256_set1_ps(1 - b1), vb2 = _mm256_set1_ps(b2),
               vb2c = _mm256_set1_ps(1 - b2), vstep = _mm256_set1_ps(step), vbc2 = _mm256_set1_ps(inv_sqrt_bc2),
               veps = _mm256_set1_ps(e);
  const __m256i lane =
      _mm256_mullo_epi32(_mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7), _mm256_set1_epi32(int(0x9E3779B9u)));
  const __m256i low16 = _mm256_set1_epi32(0xFFFF);
  auto hash8 = [](__m256i h) {
    h = _mm256_xor_si256(h, _mm256_srli_epi32(h, 16));
    h = _mm256_mullo_epi32(h, _mm256_set1_epi32(int(0x85EBCA6Bu)));
    h = _mm256_xor_si256(h, _mm256_srli_epi32(h, 13));
    h = _mm256_mullo_epi32(h, _mm256_set1_epi32(int(0xC2B2AE35u)));
    return _mm256_xor_si256(h, _mm256_srli_epi32(h, 16));
  };
  auto narrow = [](__m256i a, __m256i b) {  // the high halves of 2 x 8 floats -> 16 bf16 in order
    return _mm256_permute4x64_epi64(_mm256_packus_epi32(_mm256_srli_epi32(a, 16), _mm256_srli_epi32(b, 16)), 0xD8);
  };
  for (; c + 16 <= d; c += 16) {
    const __m256i m16 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(m + c));
    const __m256i v16 = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(v + c));
    __m256i mo[2], vo[2];
    for (int h = 0; h < 2; ++h) {
      const int cc = c + 8 * h;
      const __m256 mf = _mm256_castsi256_ps(
          _mm256_slli_epi32(_mm256_cvtepu16_epi32(h ? _mm256_extracti128_si256(m16, 1) : _mm256_castsi256_si128(m16)),
                            16));
      const __m256 vf = _mm256_castsi256_ps(
          _mm256_slli_epi32(_mm256_cvtepu16_epi32(h ? _mm256_extracti128_si256(v16, 1) : _mm256_castsi256_si128(v16)),
                            16));
      const __m256 g8 = _mm256_loadu_ps(g + cc);
      const __m256 mi = _mm256_fmadd_ps(vb1, mf, _mm256_mul_ps(vb1c, g8));
      const __m256 vi = _mm256_fmadd_ps(vb2, vf, _mm256_mul_ps(vb2c, _mm256_mul_ps(g8, g8)));
      const __m256i seed = _mm256_add_epi32(_mm256_set1_epi32(int(base + uint32_t(cc) * 0x9E3779B9u)), lane);
      const __m256i r = hash8(seed);
      mo[h] = _mm256_add_epi32(_mm256_castps_si256(mi), _mm256_and_si256(r, low16));
      vo[h] = _mm256_add_epi32(_mm256_castps_si256(vi), _mm256_srli_epi32(r, 16));
      const __m256 den = _mm256_fmadd_ps(_mm256_sqrt_ps(vi), vbc2, veps);
      store_x8(x + cc, _mm256_sub_ps(load_x8(x + cc), _mm256_div_ps(_mm256_mul_ps(vstep, mi), den)), r);
    }
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(m + c), narrow(mo[0], mo[1]));
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(v + c), narrow(vo[0], vo[1]));
  }
#endif
  // The columns after the last block of 16. (Their v rounds ((1 - b2) g) g where the blocks round (1 - b2) (g g):
  // one float unit apart in about 10 % of cases before the bfloat16 rounding. Kept as it was, so that results
  // stay bit for bit those of before; D = 512 has no such columns.)
  for (; c < d; ++c) {
    const float mi = b1 * bf16_to_float(m[c]) + (1 - b1) * g[c];
    const float vi = b2 * bf16_to_float(v[c]) + (1 - b2) * g[c] * g[c];
    const uint32_t r = hash32(base + uint32_t(c) * 0x9E3779B9u);
    m[c] = float_to_bf16_stochastic(mi, r);
    v[c] = float_to_bf16_stochastic(vi, r >> 16);
    store_x(x, c, load_x(x, c) - step * mi / (std::sqrt(vi) * inv_sqrt_bc2 + e), x_bits(r));
  }
}

}  // namespace

bool set_adam_avx512(bool on) {
#ifdef HGS_ADAM_AVX512
  if (on && !adam_avx512_default()) return false;
  adam_avx512_flag().store(on, std::memory_order_relaxed);
  return true;
#else
  return !on;
#endif
}

bool adam_avx512() { return adam_avx512_flag().load(std::memory_order_relaxed); }

template <class X>
void Adam::update_row(AdamParam& p, X* value, long row, const float* g) const {
  check_rows(p, int(p.rows()));
  p.nonfinite += row_kernel(p, value, row, g, row_step(p, ++p.step));
}

Adam::RowStep Adam::row_step(const AdamParam& p, long ts) const {
  const double t = double(std::max(1L, ts));
  return {ts, p.lr[0] * lr_scale / float(1.0 - std::pow(double(beta1), t)),
          float(1.0 / std::sqrt(1.0 - std::pow(double(beta2), t)))};
}

template <class X>
int Adam::row_kernel(AdamParam& p, X* value, long row, const float* g, const RowStep& s) const {
  const int d = p.dim;
  int bad = 0;
#pragma omp simd reduction(+ : bad)
  for (int c = 0; c < d; ++c) bad += nonfinite_bit(g[c]);
  const size_t o = size_t(row) * d;
  const uint32_t base = uint32_t(o) * 0x9E3779B9u ^ uint32_t(s.t) * 0x7FEB352Du;
  if (p.bf16)
    adam_row(p, value + o, g, nullptr, nullptr, p.m16.data() + o, p.v16.data() + o, beta1, beta2, p.eps, s.step,
             s.inv_sqrt_bc2, base);
  else
    adam_row(p, value + o, g, p.m.data() + o, p.v.data() + o, nullptr, nullptr, beta1, beta2, p.eps, s.step,
             s.inv_sqrt_bc2, base);
  return bad;
}

template void Adam::update_row<float>(AdamParam&, float*, long, const float*) const;
template void Adam::update_row<uint16_t>(AdamParam&, uint16_t*, long, const float*) const;
template int Adam::row_kernel<float>(AdamParam&, float*, long, const float*, const RowStep&) const;
template int Adam::row_kernel<uint16_t>(AdamParam&, uint16_t*, long, const float*, const RowStep&) const;

void Adam::gather(const std::vector<int>& src, const std::vector<char>& fresh) {
  for (auto& p : params) {
    if (p.scope != ParamScope::PerGaussian) continue;
    if (p.bf16) {
      gather_rows(p.m16, p.dim, src, fresh);
      gather_rows(p.v16, p.dim, src, fresh);
    } else {
      gather_rows(p.m, p.dim, src, fresh);
      gather_rows(p.v, p.dim, src, fresh);
    }
  }
}

const AdamParam* Adam::first_nonfinite() const {
  for (const auto& p : params)
    if (p.nonfinite > 0) return &p;
  return nullptr;
}

void Adam::clear_nonfinite() {
  for (auto& p : params) p.nonfinite = 0;
}

void Adam::reset_moments(const std::string& name) {
  AdamParam& p = get(name);
  std::fill(p.m.begin(), p.m.end(), 0.f);
  std::fill(p.v.begin(), p.v.end(), 0.f);
  std::fill(p.m16.begin(), p.m16.end(), uint16_t(0));
  std::fill(p.v16.begin(), p.v16.end(), uint16_t(0));
}

}  // namespace hgs::train
