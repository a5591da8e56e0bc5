// Box filter (window alignment, reflect-101 border) and majority filter: hand cases and brute force.
#include <gtest/gtest.h>

#include <random>

#include "core/error.h"
#include "eval/filters.h"
#include "eval_test_util.h"

using namespace hgs::eval;
using hgs::eval::test::ascii;

using hgs::eval::test::brute_box;
using hgs::eval::test::brute_majority;

TEST(EvalFilters, Reflect101) {
  // n = 4: "dcb|abcd|cba" and beyond, period 6.
  const int expect[] = {0, 1, 2, 3, 2, 1, 0, 1, 2, 3, 2, 1, 0};  // i = -6 .. 6
  for (int i = -6; i <= 6; ++i) EXPECT_EQ(reflect101(i, 4), expect[i + 6]) << i;
  EXPECT_EQ(reflect101(-3, 1), 0);
  EXPECT_EQ(reflect101(5, 1), 0);
  EXPECT_EQ(reflect101(-1, 2), 1);
  EXPECT_EQ(reflect101(2, 2), 0);
}

TEST(EvalFilters, EvenBoxWindowIsAnchoredLikeOpenCV) {
  // k = 2: anchor 1, window offsets -1..0. v = 0..8 on 3x3.
  std::vector<float> v = {0, 1, 2, 3, 4, 5, 6, 7, 8};
  auto out = box_filter(v, 3, 3, 2);
  EXPECT_FLOAT_EQ(out[0], (4 + 3 + 1 + 0) / 4.f);  // rows/cols -1 -> 1 (reflect-101)
  EXPECT_FLOAT_EQ(out[4], (0 + 1 + 3 + 4) / 4.f);
  EXPECT_FLOAT_EQ(out[8], (4 + 5 + 7 + 8) / 4.f);
  EXPECT_FLOAT_EQ(out[2], (4 + 5 + 1 + 2) / 4.f);
  // k = 3 on a constant map stays constant; k = 1 is the identity.
  std::vector<float> c(20, 0.25f);
  for (float x : box_filter(c, 5, 4, 3)) EXPECT_FLOAT_EQ(x, 0.25f);
  EXPECT_EQ(box_filter(v, 3, 3, 1), v);
}

TEST(EvalFilters, BoxFilterMatchesBruteForce) {
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(-1.f, 1.f);
  const int sizes[][3] = {{37, 23, 30}, {64, 48, 30}, {12, 40, 7}, {5, 3, 4}, {1, 9, 30}, {31, 31, 31}};
  for (auto& s : sizes) {
    const int w = s[0], h = s[1], k = s[2];
    std::vector<float> v(size_t(w) * h);
    for (auto& x : v) x = u(rng);
    auto fast = box_filter(v, w, h, k), ref = brute_box(v, w, h, k);
    for (size_t i = 0; i < v.size(); ++i)
      ASSERT_NEAR(fast[i], ref[i], 1e-5) << w << "x" << h << " k " << k << " at " << i;
  }
}

TEST(EvalFilters, MajorityHandCases) {
  // An isolated pixel disappears, an isolated hole is filled.
  Mask dot = ascii({".....", ".....", "..#..", ".....", "....."});
  EXPECT_EQ(majority_filter(dot, 5, 5, 7), Mask(25, 0));
  Mask hole = ascii({"#####", "#####", "##.##", "#####", "#####"});
  EXPECT_EQ(majority_filter(hole, 5, 5, 7), Mask(25, 1));
  // Ties go to 0: 2x1 [1, 0] with a 3x3 window sees one of each everywhere.
  EXPECT_EQ(majority_filter(ascii({"#."}), 2, 1, 3), Mask(2, 0));
  // A half-plane is stable under a 3x3 window (clipped at the border).
  Mask half = ascii({"##..", "##..", "##..", "##.."});
  EXPECT_EQ(majority_filter(half, 4, 4, 3), half);
  // A 7x7 window removes 5 pixels at each corner of a 20x20 square (see test_protocols for the count).
  EXPECT_THROW(majority_filter(half, 4, 4, 4), hgs::Error);
}

TEST(EvalFilters, MajorityMatchesBruteForce) {
  std::mt19937 rng(5);
  for (int trial = 0; trial < 10; ++trial) {
    const int w = 3 + trial * 3, h = 2 + trial * 2;
    Mask m(size_t(w) * h);
    std::bernoulli_distribution b(0.3 + 0.04 * trial);
    for (auto& x : m) x = b(rng);
    for (int k : {1, 3, 5, 7})
      ASSERT_EQ(majority_filter(m, w, h, k), brute_majority(m, w, h, k)) << trial << " k " << k;
  }
}
