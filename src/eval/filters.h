// Image filters of the LERF-OVS evaluation protocol (LangSplat): a 'same'-size box (mean) filter on float maps
// and a majority filter on binary masks.
#pragma once
#include <cstdint>
#include <vector>

#include "eval/metrics.h"

namespace hgs::eval {

// Index of sample i in a line of n samples under OpenCV's BORDER_REFLECT_101 ("gfedcb|abcdefgh|gfedcba"),
// repeated as often as needed for windows wider than the line; n == 1 maps everything to 0.
int reflect101(int i, int n);

// 'Same'-size box filter: out[y, x] = mean of v[reflect101(y + dy), reflect101(x + dx)] over
// dy, dx in [-a, k - 1 - a] with the anchor a = k / 2 (integer division). This is the window of
// cv2.filter2D(v, -1, ones(k, k) / k^2) that LangSplat uses (default anchor = kernel centre, default border
// BORDER_REFLECT_101); for k = 30 the window spans offsets -15 .. +14. Accumulates in double.
std::vector<float> box_filter(const std::vector<float>& v, int width, int height, int k);  // [H, W] -> [H, W]

// Majority filter with a k x k window centred on the pixel (k odd, radius r = k / 2), clipped to the image:
// out = 1 iff more than half of the in-image window pixels are inside; a tie gives 0 (like numpy's argmax of a
// bincount, which picks the lower label). Note: LangSplat's smooth() slices rows/columns up to min(i+r+1, h-1)
// and so never looks at the last row and column; we use the full clipped window instead.
Mask majority_filter(const Mask& m, int width, int height, int k);  // [H, W] -> [H, W] 0/1

}  // namespace hgs::eval
