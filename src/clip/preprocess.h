// CLIP image preprocessing and the resampling it needs.
//   resize_aa: separable antialiased bicubic (Keys a = -0.5, kernel support widened by the scale factor when
//     shrinking, weights renormalised at the borders) — the filter of PIL's Image.resize(BICUBIC) that CLIP's
//     preprocessing uses, and of torch.nn.functional.interpolate(mode="bicubic", antialias=True). Works in
//     float without PIL's 8-bit rounding.
//     With AaFilter::Bilinear the same with the triangle filter (support 1 widened likewise): PIL's
//     Image.resize(BILINEAR) and interpolate(mode="bilinear", antialias=True), SAM's preprocessing (src/sam).
//   resize_bicubic: torch.nn.functional.interpolate(mode="bicubic", align_corners=False) without antialias
//     (a = -0.75, clamped border taps), used to interpolate positional embeddings to other grids.
//   clip_preprocess: resize the shorter side to S (the longer to floor(S * long / short)), centre crop S x S
//     (offsets rounded like torchvision), subtract CLIP's mean and divide by its std.
#pragma once
#include <vector>

#include "core/image.h"

namespace hgs::clip {

inline constexpr float kClipMean[3] = {0.48145466f, 0.4578275f, 0.40821073f};
inline constexpr float kClipStd[3] = {0.26862954f, 0.26130258f, 0.27577711f};

enum class AaFilter { Bicubic, Bilinear };

// src [h, w, c] -> [oh, ow, c].
std::vector<float> resize_aa(const float* src, int h, int w, int c, int oh, int ow,
                             AaFilter filter = AaFilter::Bicubic);
std::vector<float> resize_bicubic(const float* src, int h, int w, int c, int oh, int ow);

// In place on x [pixels, 3].
void clip_normalize(float* x, size_t pixels);

// CLIP's global-embedding preprocessing of an RGB image: [S, S, 3], normalised.
std::vector<float> clip_preprocess(const Image& img, int size);

}  // namespace hgs::clip
