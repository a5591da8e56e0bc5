// The benchmark scene shared by bench_train, bench_hybrid and bench_scale: a 320x240 camera (or W x H) at the origin
// looking down +z (fx = fy = 300), optionally moved along x, and Gaussians uniform in the box [-2.5, 2.5] x [-1.9, 1.9]
// x [3, 7] with log-uniform scales in [0.01, 0.06] x `scale`, random rotations, opacity U[0.05, 0.95], SH degree 3 with
// DC N(0, 0.5) and higher coefficients N(0, 0.1).
#pragma once
#include <cmath>
#include <random>

#include "model/gaussian_model.h"
#include "render/renderer.h"

namespace hgs::bench {

constexpr int kW = 320, kH = 240, kN = 30000;

// fx = fy = 300 W / 320: the same field of view at every size.
inline render::Camera bench_camera(float x = 0.f, int W = kW, int H = kH) {
  render::Camera c;
  c.width = W;
  c.height = H;
  c.fx = c.fy = 300.f * float(W) / float(kW);
  c.cx = 0.5f * float(W);
  c.cy = 0.5f * float(H);
  c.t[0] = x;
  return c;
}

inline GaussianModel bench_model(unsigned seed, int n = kN, float scale = 1.f) {
  GaussianModel m;
  m.sh_degree = 3;
  m.resize(n);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(0, 1);
  std::normal_distribution<float> N(0, 1);
  for (int i = 0; i < n; ++i) {
    float box[3] = {-2.5f + 5 * U(rng), -1.9f + 3.8f * U(rng), 3 + 4 * U(rng)};
    for (int k = 0; k < 3; ++k) {
      m.mean[i * 3 + k] = box[k];
      m.log_scale[i * 3 + k] = std::log(0.01f * scale) + (std::log(0.06f) - std::log(0.01f)) * U(rng);
    }
    for (int k = 0; k < 4; ++k) m.quat[i * 4 + k] = N(rng);
    m.opacity_logit[i] = inverse_sigmoid(0.05f + 0.9f * U(rng));
    for (int k = 0; k < 48; ++k) m.sh[i * 48 + k] = (k < 3 ? 0.5f : 0.1f) * N(rng);
  }
  return m;
}

}  // namespace hgs::bench
