// Resampling for SAM's pre- and post-processing.
//   resize_planes_bilinear: torch.nn.functional.interpolate(mode="bilinear", align_corners=False) without
//     antialiasing, on n planes [n, h, w]: source coordinate (i + 0.5) * in / out - 0.5 clamped at 0, the two
//     neighbours (upper one clamped to the last row / column) weighted linearly. Separable: rows, then columns.
//   Preprocessing uses src/nn's antialiased resize with the triangle filter (nn::resize_aa, AaFilter::Bilinear).
#pragma once
#include <vector>

namespace hgs::sam {

// The size SAM resizes an h x w image to so that its longest side is `longest` (rounded half up).
void preprocess_shape(int h, int w, int longest, int* oh, int* ow);

// src [n, h, w] (row stride w, plane stride h * w) -> [n, oh, ow]; only the top-left ch x cw of each source
// plane is used (a crop; ch = h, cw = w for all of it). With keep_h / keep_w > 0 only the top-left
// keep_h x keep_w of each output plane is computed and returned: [n, keep_h, keep_w].
std::vector<float> resize_planes_bilinear(const float* src, int n, int h, int w, int ch, int cw, int oh, int ow,
                                          int keep_h = 0, int keep_w = 0);

}  // namespace hgs::sam
