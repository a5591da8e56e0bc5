// Branch-free float exp and erf that GCC auto-vectorises (AVX2 / AVX-512), for softmax and the activations.
//   fast_exp: Cephes' expf — x = n ln2 + r with n rounded by the 1.5 * 2^23 trick, degree-6 polynomial for e^r,
//             2^n put straight into the exponent bits. Relative error ~1e-7 over [-87, 88] (input clamped).
//   fast_erf: Abramowitz & Stegun 7.1.26 (|error| <= 1.5e-7 in exact arithmetic, <= 5e-7 evaluated in float).
#pragma once
#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdint>
#include <cstring>

#include "core/sanitizers.h"

// A kernel marked HGS_AVX512_CLONE is compiled twice, for AVX-512 (x86-64-v4) and for the build's baseline
// (x86-64-v3), and the dynamic loader picks the clone the CPU runs (GCC function multiversioning): the element-wise
// loops of the transformers run twice as wide where AVX-512 exists, and the binary still runs where it does not.
// Sanitizer builds get the baseline only: the clone's resolver runs while the dynamic loader relocates, before
// the sanitizer runtime starts, and its instrumentation crashed there (ThreadSanitizer).
#if HGS_SANITIZE_ADDRESS || HGS_SANITIZE_THREAD
#define HGS_NO_CLONES 1
#elif defined(__has_feature)
#if __has_feature(memory_sanitizer)
#define HGS_NO_CLONES 1
#endif
#endif
#ifdef HGS_NO_CLONES
#define HGS_AVX512_CLONE
#else
#define HGS_AVX512_CLONE __attribute__((target_clones("arch=x86-64-v4", "default")))
#endif

namespace hgs::nn {

inline float fast_exp(float x) {
  x = std::min(std::max(x, -87.0f), 88.0f);                // min / max rather than branches: the loops vectorise
  const float t = x * 1.44269504088896341f + 12582912.0f;  // round(x / ln2) in the low mantissa bits
  const float n = t - 12582912.0f;
  const int32_t ni = std::bit_cast<int32_t>(t) - 0x4B400000;
  const float r = x - n * 0.693359375f + n * 2.12194440e-4f;
  float y = 1.9875691500e-4f;
  y = y * r + 1.3981999507e-3f;
  y = y * r + 8.3334519073e-3f;
  y = y * r + 4.1665795894e-2f;
  y = y * r + 1.6666665459e-1f;
  y = y * r + 5.0000001201e-1f;
  y = y * r * r + r + 1.0f;
  const float scale = std::bit_cast<float>((ni + 127) << 23);
  return y * scale;
}

inline float fast_erf(float x) {
  // |x| is capped at 6: beyond it the formula gives 1.0f anyway (p e^{-a^2} < 1e-16), and the cap keeps
  // e^{-a^2} from reaching the denormal range (a 20x slowdown of the GELU of large activations).
  const float a = std::min(std::fabs(x), 6.f);
  const float t = 1.0f / (1.0f + 0.3275911f * a);
  const float p = ((((1.061405429f * t - 1.453152027f) * t + 1.421413741f) * t - 0.284496736f) * t + 0.254829592f) * t;
  const float y = 1.0f - p * fast_exp(-a * a);
  return std::copysign(y, x);
}

}  // namespace hgs::nn
