// render/simd.h's helpers against their definitions: hsum8 (8 lane sums in transposing levels) bitwise equal to
// 8 calls of hsum, on random packs with mixed magnitudes and signs (where the order of additions shows).
#include <gtest/gtest.h>

#include <cstring>
#include <random>

#include "render/simd.h"

namespace hgs::render::test {
namespace {

template <class T>
void check_hsum8(uint32_t seed) {
  using P = simd::Pack<T>;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> U(-1, 1);
  std::uniform_int_distribution<int> E(-30, 30);
  for (int trial = 0; trial < 2000; ++trial) {
    P v[8];
    for (auto& p : v)
      for (int l = 0; l < simd::kLanes; ++l) p[l] = T(std::ldexp(U(rng), E(rng)));
    const P h = simd::hsum8(v);
    for (int j = 0; j < 8; ++j) {
      const T ref = simd::hsum<T>(v[j]), got = h[j];  // a copy: clang has no address of a vector lane
      ASSERT_EQ(std::memcmp(&got, &ref, sizeof(T)), 0) << "trial " << trial << " lane " << j;
    }
  }
}

TEST(Simd, Hsum8IsBitwiseEightHsumsFloat) { check_hsum8<float>(1); }
TEST(Simd, Hsum8IsBitwiseEightHsumsDouble) { check_hsum8<double>(2); }

}  // namespace
}  // namespace hgs::render::test
