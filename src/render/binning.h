// 16x16 tile binning with a deterministic per-tile depth order.
//
// Each visible Gaussian covers the tiles its 3-sigma square (radius from the projection, as in 3DGS) touches.
// That set is intersected with the tiles touched by the box outside which alpha = opacity * G < 1/255 at every
// pixel (the bounding box of the ellipse d^T conic d <= 2 ln(255 opacity), with a small safety margin): the dropped
// tiles would only hold skipped (alpha < 1/255) pixels, so the image is exactly the 3DGS one, just with fewer
// tile/Gaussian pairs. The same opacity box (in pixels) is kept per Gaussian so the rasterizer can skip pixel
// batches it cannot touch.
// Order: visible Gaussians are radix-sorted by depth (stable, so ties keep index order), then scattered into the
// tile lists in that order (counting sort by tile), so each tile list is sorted by (depth, index).
// Pairs are numbered Gaussian-major (pair_offset[g] + row-major position inside the Gaussian's tile rect) so
// per-pair gradients can be reduced per Gaussian in a fixed order.
#pragma once
#include <cstdint>
#include <vector>

namespace hgs::render {

constexpr int kTileSize = 16;

struct Binning {
  int width = 0, height = 0, tiles_x = 0, tiles_y = 0, num_tiles = 0, num_pairs = 0;
  std::vector<int> bbox;         // [N, 4] pixel box (x0, x1, y0, y1) inclusive where alpha >= 1/255 is possible
  std::vector<double> mahal;     // [N] squared Mahalanobis radius (with margin) beyond which alpha < 1/255
  std::vector<int> trect;        // [N, 4] tile rect (tx0, tx1, ty0, ty1) inclusive; empty when x0 > x1
  std::vector<int> pair_offset;  // [N + 1] Gaussian-major pair numbering
  std::vector<int> tile_start;   // [num_tiles + 1] ranges into tile_gauss / tile_pair
  std::vector<int> tile_gauss;   // [P] Gaussian index, sorted by (depth, index) inside each tile
  std::vector<int> tile_pair;    // [P] pair id of the same entry
  // scratch kept between calls
  std::vector<uint64_t> keys, keys_tmp;
  std::vector<int> order, order_tmp, counts;
  std::vector<int> cursor;       // [threads, num_tiles] per-chunk tile counts, then write cursors
  std::vector<int> sorted_rect;  // [M, 4] trect of the binned Gaussians in depth order (read in sequence)
};

// Bins N projected Gaussians (radius[i] == 0 means culled) for an image of width x height.
template <class T>
void bin_gaussians(int width, int height, int n,
                   const T* mean2d,    // [N, 2]
                   const T* conic,     // [N, 3]
                   const T* opacity,   // [N] (after the sigmoid)
                   const T* depth,     // [N]
                   const int* radius,  // [N]
                   Binning& b);

extern template void bin_gaussians<float>(int, int, int, const float*, const float*, const float*, const float*,
                                          const int*, Binning&);
extern template void bin_gaussians<double>(int, int, int, const double*, const double*, const double*, const double*,
                                           const int*, Binning&);

}  // namespace hgs::render
