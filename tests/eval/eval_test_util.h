// Small helpers shared by the eval tests: masks from ASCII art and naive reference implementations.
#pragma once
#include <string>
#include <vector>

#include "eval/metrics.h"

namespace hgs::eval::test {

// Rows of '#' (inside) and '.' (outside), all the same length.
inline Mask ascii(const std::vector<std::string>& rows) {
  Mask m;
  for (auto& r : rows)
    for (char c : r) m.push_back(c == '#' ? 1 : 0);
  return m;
}

// Naive erosion: pixel survives iff every pixel within Chebyshev distance r is inside the image and inside.
inline Mask naive_erode_zero_pad(const Mask& m, int w, int h, int r) {
  Mask out(m.size(), 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      bool ok = true;
      for (int dy = -r; dy <= r && ok; ++dy)
        for (int dx = -r; dx <= r && ok; ++dx) {
          int xx = x + dx, yy = y + dy;
          ok = xx >= 0 && yy >= 0 && xx < w && yy < h && m[size_t(yy) * w + xx];
        }
      out[size_t(y) * w + x] = ok;
    }
  return out;
}

// Independent reflect-101: mirror about the end samples until inside.
inline int mirror(int i, int n) {
  if (n == 1) return 0;
  while (i < 0 || i >= n) {
    if (i < 0) i = -i;
    if (i >= n) i = 2 * (n - 1) - i;
  }
  return i;
}

inline std::vector<float> brute_box(const std::vector<float>& v, int w, int h, int k) {
  const int a = k / 2;
  std::vector<float> out(v.size());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      double s = 0;
      for (int dy = -a; dy <= k - 1 - a; ++dy)
        for (int dx = -a; dx <= k - 1 - a; ++dx) s += v[size_t(mirror(y + dy, h)) * w + mirror(x + dx, w)];
      out[size_t(y) * w + x] = static_cast<float>(s / (k * k));
    }
  return out;
}

inline Mask brute_majority(const Mask& m, int w, int h, int k) {
  const int r = k / 2;
  Mask out(m.size());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      int ones = 0, n = 0;
      for (int yy = y - r; yy <= y + r; ++yy)
        for (int xx = x - r; xx <= x + r; ++xx)
          if (xx >= 0 && yy >= 0 && xx < w && yy < h) {
            ++n;
            ones += m[size_t(yy) * w + xx] != 0;
          }
      out[size_t(y) * w + x] = ones > n - ones;
    }
  return out;
}

}  // namespace hgs::eval::test
