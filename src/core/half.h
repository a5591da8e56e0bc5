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

}  // namespace hgs
