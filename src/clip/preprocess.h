// CLIP image preprocessing (the resampling itself is nn/resize.h).
//   clip_preprocess: resize the shorter side to S (the longer to floor(S * long / short)) with nn::resize_aa's
//     bicubic filter, centre crop S x S (offsets rounded like torchvision), subtract CLIP's mean and divide by its
//     std.
#pragma once
#include <vector>

#include "core/image.h"

namespace hgs::clip {

inline constexpr float kClipMean[3] = {0.48145466f, 0.4578275f, 0.40821073f};
inline constexpr float kClipStd[3] = {0.26862954f, 0.26130258f, 0.27577711f};

// In place on x [pixels, 3].
void clip_normalize(float* x, size_t pixels);

// CLIP's global-embedding preprocessing of an RGB image: [S, S, 3], normalised.
std::vector<float> clip_preprocess(const Image& img, int size);

}  // namespace hgs::clip
