// The adaptive batch rule's gain (batch_gain.h has the derivation).
#include "train/batch_gain.h"

#include <algorithm>
#include <cmath>
#include <vector>

namespace hgs::train {

double squared_norm(const float* x, size_t n) {
  constexpr size_t kChunk = size_t(1) << 14;  // fixed chunks: their sums do not depend on the threads
  const long chunks = long((n + kChunk - 1) / kChunk);
  std::vector<double> part(static_cast<size_t>(chunks));
#pragma omp parallel for schedule(static)
  for (long c = 0; c < chunks; ++c) {
    const size_t b = size_t(c) * kChunk, e = std::min(n, b + kChunk);
    double s = 0;
#pragma omp simd reduction(+ : s)
    for (size_t i = b; i < e; ++i) s += double(x[i]) * double(x[i]);
    part[size_t(c)] = s;
  }
  double s = 0;
  for (double v : part) s += v;
  return s;
}

float adaptive_gain(AdamParam& p, double batch_sq, double view_sq, int G, double beta) {
  p.gain_batch = beta * p.gain_batch + (1 - beta) * batch_sq;
  p.gain_view = beta * p.gain_view + (1 - beta) * view_sq;
  if (!(p.gain_view > 0) || G <= 1) {
    p.lr_mult = 1.f;
    return p.lr_mult;
  }
  const double r = std::clamp(p.gain_batch / p.gain_view, 1.0 / G, 1.0);  // [1 / G, 1] up to rounding
  p.lr_mult = float(std::sqrt(G * r));
  return p.lr_mult;
}

}  // namespace hgs::train
