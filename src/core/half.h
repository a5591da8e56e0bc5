// IEEE-754 binary16 <-> float conversion (F16C instructions are part of the x86-64-v3 baseline).
#pragma once
#include <immintrin.h>

#include <cstdint>

namespace hgs {

inline float half_to_float(uint16_t h) { return _cvtsh_ss(h); }
inline uint16_t float_to_half(float f) { return _cvtss_sh(f, _MM_FROUND_TO_NEAREST_INT); }

// bfloat16: the top 16 bits of a float32.
inline float bf16_to_float(uint16_t b) {
  uint32_t u = static_cast<uint32_t>(b) << 16;
  float f;
  __builtin_memcpy(&f, &u, 4);
  return f;
}

// float -> bfloat16 with stochastic rounding: `r` (uniform 16 random bits) is added below the kept bits before
// truncation, so the rounding is unbiased: E[bf16(x)] = x. Round-to-nearest would stall an Adam second moment,
// whose per-step relative change (1 - beta2 = 0.1%) is below half a bf16 unit (0.2%). Finite inputs only.
inline uint16_t float_to_bf16_stochastic(float f, uint32_t r) {
  uint32_t u;
  __builtin_memcpy(&u, &f, 4);
  return static_cast<uint16_t>((u + (r & 0xFFFFu)) >> 16);
}

// float -> IEEE half with stochastic rounding: `r` supplies the 13 bits a half drops below a float's
// mantissa (added before rounding toward zero), so E[half(x)] = x in the normal half range.
inline uint16_t float_to_half_stochastic(float f, uint32_t r) {
  uint32_t u;
  __builtin_memcpy(&u, &f, 4);
  u += r & 0x1FFFu;
  __builtin_memcpy(&f, &u, 4);
  return _cvtss_sh(f, _MM_FROUND_TO_ZERO | _MM_FROUND_NO_EXC);
}

// float -> bfloat16, round to nearest even; NaN stays a (quiet) NaN, infinities stay infinite. Branch-free
// (a select), so loops over it vectorise.
inline uint16_t float_to_bf16(float f) {
  uint32_t u;
  __builtin_memcpy(&u, &f, 4);
  const uint16_t r = static_cast<uint16_t>((u + 0x7FFFu + ((u >> 16) & 1u)) >> 16);
  return (u & 0x7FFFFFFFu) > 0x7F800000u ? uint16_t(0x7FC0u) : r;
}

// A counter-based 32-bit hash (murmur3 finaliser) for reproducible per-element random bits.
inline uint32_t hash32(uint32_t x) {
  x ^= x >> 16;
  x *= 0x85EBCA6Bu;
  x ^= x >> 13;
  x *= 0xC2B2AE35u;
  x ^= x >> 16;
  return x;
}

}  // namespace hgs
