// Box filter: separable running sums, O(H W) whatever the window: along each row (padded by reflection),
// then down the columns with one accumulator per column, updated row by row. Majority filter: a summed-area
// table of the mask gives each clipped window's count of inside pixels in O(1).
#include "eval/filters.h"

#include <algorithm>

#include "core/error.h"

namespace hgs::eval {

int reflect101(int i, int n) {
  if (n <= 1) return 0;
  const int period = 2 * (n - 1);
  i %= period;
  if (i < 0) i += period;
  return i < n ? i : period - i;
}

std::vector<float> box_filter(const std::vector<float>& v, int width, int height, int k) {
  if (width <= 0 || height <= 0 || v.size() != size_t(width) * height)
    fail("eval: box filter input holds {} values, expected {}x{}", v.size(), width, height);
  if (k < 1) fail("eval: box filter size must be >= 1, got {}", k);
  const int a = k / 2, lo = -a, hi = k - 1 - a;
  // Horizontal pass: each row padded by reflection once, then a running window sum.
  std::vector<double> rows(v.size());
  std::vector<double> pad(size_t(width) + k);
  for (int y = 0; y < height; ++y) {
    const float* src = &v[size_t(y) * width];
    for (int j = 0; j < width + k - 1; ++j) pad[j] = src[reflect101(j + lo, width)];  // pad[j] = sample j + lo
    double s = 0;
    for (int j = 0; j < k; ++j) s += pad[j];
    double* dst = &rows[size_t(y) * width];
    for (int x = 0; x < width; ++x) {
      dst[x] = s;
      s += pad[x + k] - pad[x];
    }
  }
  // Vertical pass: one running sum per column, updated a whole row at a time (contiguous memory).
  std::vector<float> out(v.size());
  const double inv = 1.0 / (double(k) * k);
  std::vector<double> acc(width, 0.0);
  for (int dy = lo; dy <= hi; ++dy) {
    const double* r = &rows[size_t(reflect101(dy, height)) * width];
    for (int x = 0; x < width; ++x) acc[x] += r[x];
  }
  for (int y = 0; y < height; ++y) {
    float* dst = &out[size_t(y) * width];
    for (int x = 0; x < width; ++x) dst[x] = static_cast<float>(acc[x] * inv);
    if (y + 1 == height) break;
    const double* add = &rows[size_t(reflect101(y + hi + 1, height)) * width];
    const double* sub = &rows[size_t(reflect101(y + lo, height)) * width];
    for (int x = 0; x < width; ++x) acc[x] += add[x] - sub[x];
  }
  return out;
}

Mask majority_filter(const Mask& m, int width, int height, int k) {
  if (width <= 0 || height <= 0 || m.size() != size_t(width) * height)
    fail("eval: majority filter input holds {} pixels, expected {}x{}", m.size(), width, height);
  if (k < 1 || k % 2 == 0) fail("eval: majority filter size must be odd and >= 1, got {}", k);
  const int r = k / 2;
  // sat[(y) * (W + 1) + x] = inside pixels in [0, y) x [0, x).
  std::vector<long> sat(size_t(width + 1) * (height + 1), 0);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x)
      sat[size_t(y + 1) * (width + 1) + x + 1] =
          (m[size_t(y) * width + x] ? 1 : 0) + sat[size_t(y) * (width + 1) + x + 1] +
          sat[size_t(y + 1) * (width + 1) + x] - sat[size_t(y) * (width + 1) + x];
  Mask out(m.size());
  for (int y = 0; y < height; ++y) {
    const int y0 = std::max(0, y - r), y1 = std::min(height, y + r + 1);
    for (int x = 0; x < width; ++x) {
      const int x0 = std::max(0, x - r), x1 = std::min(width, x + r + 1);
      const long ones = sat[size_t(y1) * (width + 1) + x1] - sat[size_t(y0) * (width + 1) + x1] -
                        sat[size_t(y1) * (width + 1) + x0] + sat[size_t(y0) * (width + 1) + x0];
      const long n = long(y1 - y0) * (x1 - x0);
      out[size_t(y) * width + x] = 2 * ones > n ? 1 : 0;
    }
  }
  return out;
}

}  // namespace hgs::eval
