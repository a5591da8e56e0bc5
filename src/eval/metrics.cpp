// Mask metrics. Erosion by a 3x3 square applied d times equals one erosion by a (2d+1) x (2d+1) square (with
// the same constant value outside the image), which is separable: a pixel survives iff no zero lies within
// distance d along its row, then along its column. Each pass keeps a running count of zeros in the sliding
// window (the column pass one counter per column, updated a row at a time), so the cost is O(H W) whatever d is.
#include "eval/metrics.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"

namespace hgs::eval {

namespace {

void check(const Mask& m, int width, int height, const char* what) {
  if (width <= 0 || height <= 0) fail("eval: {} mask has an empty size {}x{}", what, width, height);
  if (m.size() != size_t(width) * height)
    fail("eval: {} mask holds {} pixels, expected {}x{} = {}", what, m.size(), width, height, size_t(width) * height);
}

// One separable pass: out[i] = 1 iff every sample at distance <= r along the line is non-zero (samples beyond
// the ends are `outside`). `get(i)` reads sample i of a line of length n; `put(i, v)` writes.
template <typename Get, typename Put>
void erode_line(int n, int r, uint8_t outside, Get get, Put put) {
  // zeros = number of zero samples in [i - r, i + r] (outside samples included).
  const int out_zero = outside ? 0 : 1;
  long zeros = 0;
  for (int j = -r; j <= r; ++j) zeros += (j < 0 || j >= n) ? out_zero : (get(j) ? 0 : 1);
  for (int i = 0; i < n; ++i) {
    put(i, zeros == 0 ? 1 : 0);
    int leave = i - r, enter = i + r + 1;
    zeros -= (leave < 0 || leave >= n) ? out_zero : (get(leave) ? 0 : 1);
    zeros += (enter < 0 || enter >= n) ? out_zero : (get(enter) ? 0 : 1);
  }
}

}  // namespace

Confusion confusion(const Mask& gt, const Mask& pred, int width, int height) {
  check(gt, width, height, "ground-truth");
  check(pred, width, height, "predicted");
  Confusion c;
  for (size_t i = 0; i < gt.size(); ++i) {
    const bool g = gt[i] != 0, p = pred[i] != 0;
    if (g && p) ++c.tp;
    else if (p) ++c.fp;
    else if (g) ++c.fn;
    else ++c.tn;
  }
  return c;
}

double iou(const Mask& gt, const Mask& pred, int width, int height) {
  Confusion c = confusion(gt, pred, width, height);
  const long uni = c.tp + c.fp + c.fn;
  return uni == 0 ? 1.0 : double(c.tp) / double(uni);
}

double pixel_accuracy(const Mask& gt, const Mask& pred, int width, int height) {
  Confusion c = confusion(gt, pred, width, height);
  return double(c.tp + c.tn) / double(gt.size());
}

int boundary_width(int width, int height) {
  const double diag = std::sqrt(double(width) * width + double(height) * height);
  return std::max(1, static_cast<int>(std::nearbyint(0.02 * diag)));  // ties to even, like Python's round()
}

Mask erode3x3(const Mask& m, int width, int height, int iterations, uint8_t outside_value) {
  check(m, width, height, "eroded");
  Mask out(m.size());
  if (iterations <= 0) {
    for (size_t i = 0; i < m.size(); ++i) out[i] = m[i] ? 1 : 0;
    return out;
  }
  const int r = iterations;
  Mask tmp(m.size());
  for (int y = 0; y < height; ++y) {
    const uint8_t* row = &m[size_t(y) * width];
    uint8_t* dst = &tmp[size_t(y) * width];
    erode_line(
        width, r, outside_value, [&](int x) { return row[x] != 0; }, [&](int x, uint8_t v) { dst[x] = v; });
  }
  // Vertical pass, row by row: zeros[x] = zero samples of column x in rows [y - r, y + r].
  const int out_zero = outside_value ? 0 : 1;
  std::vector<int> zeros(width, 0);
  auto add_row = [&](int yy, int sign) {
    if (yy < 0 || yy >= height) {
      if (out_zero)
        for (int x = 0; x < width; ++x) zeros[x] += sign;
      return;
    }
    const uint8_t* row = &tmp[size_t(yy) * width];
    for (int x = 0; x < width; ++x) zeros[x] += sign * (row[x] ? 0 : 1);
  };
  for (int yy = -r; yy <= r; ++yy) add_row(yy, 1);
  for (int y = 0; y < height; ++y) {
    uint8_t* dst = &out[size_t(y) * width];
    for (int x = 0; x < width; ++x) dst[x] = zeros[x] == 0 ? 1 : 0;
    add_row(y - r, -1);
    add_row(y + r + 1, 1);
  }
  return out;
}

Mask boundary_region(const Mask& m, int width, int height, int d) {
  Mask er = erode3x3(m, width, height, d, 0);
  Mask b(m.size());
  for (size_t i = 0; i < m.size(); ++i) b[i] = (m[i] && !er[i]) ? 1 : 0;
  return b;
}

double boundary_iou(const Mask& gt, const Mask& pred, int width, int height, int d) {
  check(gt, width, height, "ground-truth");
  check(pred, width, height, "predicted");
  if (d <= 0) d = boundary_width(width, height);
  const Confusion c =
      confusion(boundary_region(gt, width, height, d), boundary_region(pred, width, height, d), width, height);
  const long uni = c.tp + c.fp + c.fn;
  return uni == 0 ? std::numeric_limits<double>::quiet_NaN() : double(c.tp) / double(uni);
}

MaskScores score_mask(const Mask& gt, const Mask& pred, int width, int height, int d) {
  MaskScores s;
  s.iou = iou(gt, pred, width, height);
  s.acc = pixel_accuracy(gt, pred, width, height);
  s.biou = boundary_iou(gt, pred, width, height, d);
  return s;
}

}  // namespace hgs::eval
