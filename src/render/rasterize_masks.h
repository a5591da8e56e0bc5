// Per-tile batch masks of the forward kernels (rasterize_forward.cpp, rasterize_pixels.cpp): which 8-pixel
// batches of a tile each of its Gaussians can reach with alpha >= 1/255. Included inside the ISA region
// (raster_isa_begin.h) of each kernel file, after it: build_masks uses the region's instruction sets.
#pragma once
#include <cstdint>

#include "render/rasterize_common.h"

namespace hgs::render::HGS_RASTER_NS::detail {

// Spreads the low 16 bits of x to the even bit positions.
inline uint32_t spread_bits(uint32_t x) {
  x = (x | (x << 8)) & 0x00FF00FFu;
  x = (x | (x << 4)) & 0x0F0F0F0Fu;
  x = (x | (x << 2)) & 0x33333333u;
  x = (x | (x << 1)) & 0x55555555u;
  return x;
}

// Batch masks of a tile, masks [n] (build_masks; batch_mask for one Gaussian): bit (row * 2 + half) is set when
// the Gaussian can reach the 8-pixel batch (half a row) with alpha >= 1/255. For each of the 16 pixel rows the
// exact x-interval where d^T conic d <= m (the alpha >= 1/255 region, with margin; binning.h) is computed in
// double, kMaskRows rows per vector (8 in the AVX-512 compilation, 4 otherwise: the same operations on every row,
// so the same masks).
#if defined(HGS_RASTER_AVX512) && defined(__GNUC__) && !defined(__clang__)
constexpr int kMaskRows = 8;
#else
constexpr int kMaskRows = 4;
#endif
typedef double MaskRowsD __attribute__((vector_size(8 * kMaskRows)));
typedef int64_t MaskRowsL __attribute__((vector_size(8 * kMaskRows)));

// A tile's rows and batch columns as the masks test them.
struct MaskTile {
  static constexpr int NQ = kTileSize / kMaskRows;
  int ty0;
  MaskRowsD rowc[NQ];  // pixel-centre y of the tile rows
  double bx0[2], bx1[2];
  MaskTile(const Binning& bins, int tile) {
    const int tx0 = (tile % bins.tiles_x) * kTileSize;
    ty0 = (tile / bins.tiles_x) * kTileSize;
    for (int q = 0; q < NQ; ++q)
      for (int l = 0; l < kMaskRows; ++l) rowc[q][l] = ty0 + kMaskRows * q + l + 0.5;
    bx0[0] = double(tx0);
    bx0[1] = double(tx0 + kLanes);
    bx1[0] = double(tx0 + kLanes - 1);
    bx1[1] = double(tx0 + 2 * kLanes - 1);
  }
};

// One Gaussian's batch mask in the tile (record r).
template <class T>
inline __attribute__((always_inline)) uint32_t batch_mask(const T* r, const MaskTile& g) {
  typedef MaskRowsD vd;
  typedef MaskRowsL vl;
  const double ey = double(r[kEy]);
  const double u = double(r[kMx]), v = double(r[kMy]);
  if (ey < 0 || v + ey - 0.5 < g.ty0 || v - ey - 0.5 > g.ty0 + kTileSize - 1) return 0;
  const double a = double(r[kA]), b = double(r[kB]), c = double(r[kC]);
  const double m = double(r[kMahal]), ndet = b * b - a * c, am = a * m, ia = 1.0 / a;
  uint32_t hit[2] = {0, 0};
  for (int q = 0; q < MaskTile::NQ; ++q) {
    const vd dy = v - g.rowc[q];
    const vd disc = dy * dy * ndet + am;
    const vl valid = disc >= 0.0;
    vd dc = valid ? disc : vd{};
    vd sq;
#if defined(HGS_RASTER_AVX512) && defined(__GNUC__) && !defined(__clang__)
    sq = (vd)_mm512_maskz_sqrt_pd(__mmask8(0xFF), (__m512d)dc);  // maskz: GCC 12 warns on _mm512_sqrt_pd
#elif defined(__AVX__)
    sq = (vd)_mm256_sqrt_pd((__m256d)dc);
#else
    for (int l = 0; l < kMaskRows; ++l) sq[l] = std::sqrt(dc[l]);
#endif
    // pixel x (centre x + 0.5) with dx = u - x - 0.5 in [(-b dy - sq) / a, (-b dy + sq) / a]
    const vd xl = u - (sq - b * dy) * ia - (0.5 + 1e-3);
    const vd xr = u + (sq + b * dy) * ia - (0.5 - 1e-3);
    for (int h = 0; h < kBatchesPerRow; ++h) {
      const vl hm = valid & (xl <= g.bx1[h]) & (xr >= g.bx0[h]);
#if defined(HGS_RASTER_AVX512) && defined(__GNUC__) && !defined(__clang__)
      hit[h] |= uint32_t(_mm512_movepi64_mask((__m512i)hm)) << (kMaskRows * q);
#elif defined(__AVX__)
      hit[h] |= uint32_t(_mm256_movemask_pd((__m256d)hm)) << (kMaskRows * q);
#else
      for (int l = 0; l < kMaskRows; ++l) hit[h] |= uint32_t(hm[l] & 1) << (kMaskRows * q + l);
#endif
    }
  }
  return spread_bits(hit[0]) | (spread_bits(hit[1]) << 1);
}

template <class T>
void build_masks(const Binning& bins, int tile, const TileData<T>& td, uint32_t* masks) {
  const MaskTile g(bins, tile);
  for (int k = 0; k < td.n; ++k) masks[k] = batch_mask(td.rec + size_t(k) * kRecord, g);
}

}  // namespace hgs::render::HGS_RASTER_NS::detail
