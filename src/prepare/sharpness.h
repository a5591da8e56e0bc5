// Blur detection for video frames: sharpness = variance of the 3x3 Laplacian (4-neighbour: centre x -4 + up,
// down, left, right) of the grey image over its interior pixels; a frame is kept when its sharpness is at least
// `keep` x the median sharpness of the frames within +-`radius` of it (itself included, clipped at the ends), so
// a short run of motion-blurred frames (fewer than radius + 1 in a row) is dropped while a scene that is soft
// throughout is kept.
#pragma once
#include <cstdint>
#include <vector>

namespace hgs::prepare {

// grey: [H, W] in 0..255. 0 for images smaller than 3x3.
double laplacian_variance(const uint8_t* grey, int width, int height);

// keep[i] for each frame of `sharpness` (in order).
std::vector<bool> keep_sharp_frames(const std::vector<double>& sharpness, double keep, int radius = 5);

}  // namespace hgs::prepare
