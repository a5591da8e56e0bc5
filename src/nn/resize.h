// Image and grid resampling for the CLIP and SAM preprocessing.
//   resize_aa: separable antialiased bicubic (Keys a = -0.5, kernel support widened by the scale factor when
//     shrinking, weights renormalised at the borders) — the filter of PIL's Image.resize(BICUBIC) that CLIP's
//     preprocessing uses, and of torch.nn.functional.interpolate(mode="bicubic", antialias=True). Works in
//     float without PIL's 8-bit rounding.
//     With AaFilter::Bilinear the same with the triangle filter (support 1 widened likewise): PIL's
//     Image.resize(BILINEAR) and interpolate(mode="bilinear", antialias=True), SAM's preprocessing (src/sam).
//   resize_bicubic: torch.nn.functional.interpolate(mode="bicubic", align_corners=False) without antialias
//     (a = -0.75, clamped border taps), used to interpolate positional embeddings to other grids.
#pragma once
#include <vector>

namespace hgs::nn {

enum class AaFilter { Bicubic, Bilinear };

// src [h, w, c] -> [oh, ow, c].
std::vector<float> resize_aa(const float* src, int h, int w, int c, int oh, int ow,
                             AaFilter filter = AaFilter::Bicubic);
std::vector<float> resize_bicubic(const float* src, int h, int w, int c, int oh, int ow);

}  // namespace hgs::nn
