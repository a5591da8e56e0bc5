// tile_pixels (rasterize.h): a per-pixel choice [H, W] regrouped by 16x16 tile for rasterize_depth_at, each tile's
// chosen pixels quadrant by quadrant. Two passes over each row of tiles (count, then write at the prefix sums of
// the counts), parallel over tile rows.
#include <algorithm>
#include <vector>

#include "render/rasterize.h"

namespace hgs::render {

void tile_pixels(int width, int height, const uint8_t* chosen, TilePixels& px) {
  const int tx = (width + kTileSize - 1) / kTileSize, ty = (height + kTileSize - 1) / kTileSize;
  px.start.assign(size_t(tx) * ty + 1, 0);
  int* count = px.start.data() + 1;  // tile t's count at start[t + 1] until the prefix sum
#pragma omp parallel for schedule(static)
  for (int r = 0; r < ty; ++r)
    for (int y = r * kTileSize; y < std::min(height, (r + 1) * kTileSize); ++y)
      for (int x = 0; x < width; ++x) count[size_t(r) * tx + x / kTileSize] += chosen[size_t(y) * width + x] != 0;
  for (size_t t = 0; t + 1 < px.start.size(); ++t) px.start[t + 1] += px.start[t];
  px.pixel.resize(size_t(px.start.back()));
  constexpr int Q = kTileSize / 2;
#pragma omp parallel for schedule(static)
  for (int r = 0; r < ty; ++r)
    for (int c = 0; c < tx; ++c) {
      int o = px.start[size_t(r) * tx + c];
      for (int qy = r * kTileSize; qy < std::min(height, (r + 1) * kTileSize); qy += Q)
        for (int qx = c * kTileSize; qx < std::min(width, (c + 1) * kTileSize); qx += Q)
          for (int y = qy; y < std::min(height, qy + Q); ++y)
            for (int x = qx; x < std::min(width, qx + Q); ++x)
              if (chosen[size_t(y) * width + x]) px.pixel[o++] = y * width + x;
    }
}

}  // namespace hgs::render
