// The float array drivers sh_forward / sh_backward (8 Gaussians per vector, sh.cpp) against the scalar
// per-Gaussian templates of sh.h driven one Gaussian at a time, bit for bit (memcmp): every degree, stride 16 with
// lower degrees (rows beyond the degree zeroed), N around multiples of 8, active masks with zeros and null, a
// Gaussian exactly at the camera (zero direction), channels clamped at 0, dmean null and accumulated.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <random>
#include <string>
#include <vector>

#include "render/sh.h"

namespace hgs::render::test {
namespace {

struct ShCase {
  int n, degree, stride;
  std::vector<float> sh, mean, dcolors, campos;
  std::vector<int> active;  // empty = null
  const int* act() const { return active.empty() ? nullptr : active.data(); }
};

ShCase make_case(int n, int degree, int stride, bool with_active, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> N01(0, 1);
  std::uniform_real_distribution<float> U(-3, 3);
  ShCase c{n, degree, stride, {}, {}, {}, {U(rng), U(rng), U(rng)}, {}};
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < stride; ++k)
      for (int ch = 0; ch < 3; ++ch) c.sh.push_back(k == 0 ? 1.5f * N01(rng) : 0.3f * N01(rng));  // DC: many clamp
    for (int j = 0; j < 3; ++j) c.mean.push_back(U(rng)), c.dcolors.push_back(N01(rng));
    if (with_active) c.active.push_back(rng() % 4 == 0 ? 0 : int(rng() % 5) + 1);
  }
  // A Gaussian exactly at the camera centre (zero view direction), and one active
  const int at = n / 2;
  for (int j = 0; j < 3; ++j) c.mean[3 * at + j] = c.campos[j];
  if (with_active) c.active[at] = 1;
  return c;
}

// The scalar path: sh_eval_one / sh_backward_one one Gaussian at a time, as the drivers did before vectorising.
void ref_forward(const ShCase& c, float* colors) {
  for (int i = 0; i < c.n; ++i) {
    if (c.act() && !c.active[i]) {
      colors[3 * i] = colors[3 * i + 1] = colors[3 * i + 2] = 0;
      continue;
    }
    const float dir[3] = {c.mean[3 * i] - c.campos[0], c.mean[3 * i + 1] - c.campos[1],
                          c.mean[3 * i + 2] - c.campos[2]};
    sh_eval_one(c.degree, &c.sh[size_t(i) * c.stride * 3], dir, colors + 3 * i);
  }
}
void ref_backward(const ShCase& c, float* dsh, float* dmean) {
  const int K = sh_num_coeffs(c.degree);
  for (int i = 0; i < c.n; ++i) {
    float* d = dsh + size_t(i) * c.stride * 3;
    const bool on = !c.act() || c.active[i];
    for (int k = on ? K : 0; k < c.stride; ++k) d[3 * k] = d[3 * k + 1] = d[3 * k + 2] = 0;
    if (!on) continue;
    const float dir[3] = {c.mean[3 * i] - c.campos[0], c.mean[3 * i + 1] - c.campos[1],
                          c.mean[3 * i + 2] - c.campos[2]};
    float ddir[3] = {0, 0, 0};
    sh_backward_one(c.degree, &c.sh[size_t(i) * c.stride * 3], dir, &c.dcolors[3 * i], d, ddir);
    if (dmean)
      for (int j = 0; j < 3; ++j) dmean[3 * i + j] += ddir[j];
  }
}

bool same_bits(const std::vector<float>& a, const std::vector<float>& b) {
  return a.size() == b.size() && std::memcmp(a.data(), b.data(), a.size() * sizeof(float)) == 0;
}

// Output buffers start as NaN / random values so every element the drivers must write is checked.
std::vector<float> garbage(size_t size, uint32_t seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> N01(0, 1);
  std::vector<float> v(size);
  for (size_t i = 0; i < size; ++i) v[i] = i % 5 == 0 ? std::nanf("") : i % 7 == 0 ? -0.0f : N01(rng);
  return v;
}

TEST(ShSimd, DriversBitwiseEqualScalar) {
  int cases = 0, clamped = 0;
  const int degree_stride[][2] = {{0, 1}, {0, 16}, {1, 4}, {1, 16}, {2, 9}, {2, 16}, {3, 16}};
  for (const auto [degree, stride] : degree_stride) {
    for (int n : {1, 7, 8, 9, 1003})
      for (bool with_active : {false, true}) {
        const ShCase c = make_case(n, degree, stride, with_active, uint32_t(1000 * degree + 10 * n + stride));
        const std::string what = "degree " + std::to_string(degree) + " stride " + std::to_string(stride) + " n " +
                                 std::to_string(n) + (with_active ? " active" : " all");
        // forward
        std::vector<float> col = garbage(3 * n, 1), col_ref = col;
        sh_forward(n, degree, stride, c.sh.data(), c.mean.data(), c.campos.data(), c.act(), col.data());
        ref_forward(c, col_ref.data());
        EXPECT_TRUE(same_bits(col, col_ref)) << what;
        for (int i = 0; i < 3 * n; ++i) clamped += col_ref[i] == 0 && (!c.act() || c.active[i / 3]);
        // backward, without and with dmean (accumulated)
        for (bool with_dmean : {false, true}) {
          std::vector<float> dsh = garbage(size_t(n) * stride * 3, 2), dsh_ref = dsh;
          std::vector<float> dm = garbage(3 * n, 3);
          for (float& v : dm) v = std::isnan(v) ? 0.5f : v;  // NaN would hide the accumulation
          std::vector<float> dm_ref = dm;
          sh_backward(n, degree, stride, c.sh.data(), c.mean.data(), c.campos.data(), c.act(), c.dcolors.data(),
                      dsh.data(), with_dmean ? dm.data() : nullptr);
          ref_backward(c, dsh_ref.data(), with_dmean ? dm_ref.data() : nullptr);
          EXPECT_TRUE(same_bits(dsh, dsh_ref)) << what << (with_dmean ? " dmean" : "");
          EXPECT_TRUE(same_bits(dm, dm_ref)) << what << (with_dmean ? " dmean" : "");
        }
        ++cases;
      }
  }
  EXPECT_EQ(cases, 70);
  EXPECT_GT(clamped, 100);  // the clamp at 0 is exercised
}

// The rows beyond the active degree and all rows of inactive Gaussians are zeroed, and the Gaussian at the camera
// has the DC-only colour (zero direction: every higher basis function is 0).
TEST(ShSimd, ZeroRowsAndZeroDirection) {
  const int n = 1003, degree = 1, stride = 16;
  const ShCase c = make_case(n, degree, stride, true, 7);
  std::vector<float> dsh = garbage(size_t(n) * stride * 3, 4), col(3 * n);
  sh_backward(n, degree, stride, c.sh.data(), c.mean.data(), c.campos.data(), c.act(), c.dcolors.data(), dsh.data(),
              (float*)nullptr);
  int inactive = 0;
  for (int i = 0; i < n; ++i) {
    const int first = c.active[i] ? 3 * sh_num_coeffs(degree) : 0;
    inactive += !c.active[i];
    for (int j = first; j < 3 * stride; ++j) ASSERT_EQ(dsh[size_t(i) * stride * 3 + j], 0.0f) << i << " " << j;
  }
  EXPECT_GT(inactive, 100);
  sh_forward(n, degree, stride, c.sh.data(), c.mean.data(), c.campos.data(), c.act(), col.data());
  const int at = n / 2;
  for (int ch = 0; ch < 3; ++ch) {
    const float v = 0.28209479177387814f * c.sh[size_t(at) * stride * 3 + ch] + 0.5f;
    EXPECT_FLOAT_EQ(col[3 * at + ch], v > 0 ? v : 0.0f);  // not bitwise: the compiler may fuse v
  }
}

}  // namespace
}  // namespace hgs::render::test
