// Laplacian-variance sharpness and the local-median keep rule (sharpness.h).
#include "prepare/sharpness.h"

#include <algorithm>

namespace hgs::prepare {

double laplacian_variance(const uint8_t* g, int w, int h) {
  if (w < 3 || h < 3) return 0;
  double sum = 0, sum2 = 0;
  for (int y = 1; y < h - 1; ++y) {
    const uint8_t* r = g + size_t(y) * w;
    for (int x = 1; x < w - 1; ++x) {
      const double l = double(r[x - 1]) + r[x + 1] + r[x - w] + r[x + w] - 4.0 * r[x];
      sum += l;
      sum2 += l * l;
    }
  }
  const double n = double(w - 2) * (h - 2), mean = sum / n;
  return std::max(0.0, sum2 / n - mean * mean);
}

std::vector<bool> keep_sharp_frames(const std::vector<double>& s, double keep, int radius) {
  const int n = static_cast<int>(s.size());
  std::vector<bool> out(s.size(), true);
  for (int i = 0; i < n; ++i) {
    std::vector<double> win(s.begin() + std::max(0, i - radius), s.begin() + std::min(n, i + radius + 1));
    auto mid = win.begin() + static_cast<std::ptrdiff_t>(win.size() / 2);
    std::nth_element(win.begin(), mid, win.end());
    double median = *mid;
    if (win.size() % 2 == 0) median = 0.5 * (median + *std::max_element(win.begin(), mid));
    out[i] = s[i] >= keep * median;
  }
  return out;
}

}  // namespace hgs::prepare
