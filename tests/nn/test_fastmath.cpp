// fast_exp / fast_erf against the C library over their whole working range.
#include <gtest/gtest.h>

#include <cmath>

#include "nn/fastmath.h"

using namespace hgs::nn;

TEST(FastMath, ExpMatchesLibm) {
  double worst = 0;
  for (double x = -80; x <= 80; x += 0.001) {
    double ref = std::exp(double(float(x)));
    worst = std::max(worst, std::fabs(fast_exp(float(x)) - ref) / ref);
  }
  EXPECT_LT(worst, 3e-7);
  EXPECT_EQ(fast_exp(0.f), 1.f);
  EXPECT_LT(fast_exp(-1000.f), 1e-37f);  // clamped, no NaN
  EXPECT_TRUE(std::isfinite(fast_exp(1000.f)));
}

TEST(FastMath, ErfMatchesLibm) {
  double worst = 0;
  for (double x = -8; x <= 8; x += 0.0005)
    worst = std::max(worst, std::fabs(fast_erf(float(x)) - std::erf(double(float(x)))));
  EXPECT_LT(worst, 5e-7);  // the formula is good to 1.5e-7; float evaluation adds the rest
  EXPECT_EQ(fast_erf(0.f), 0.f);
  EXPECT_FLOAT_EQ(fast_erf(-1.f), -fast_erf(1.f));
}
