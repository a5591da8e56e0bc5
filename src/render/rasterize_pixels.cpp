// Tile rasterizer, forward at chosen pixels only: alpha and expected depth where a caller will look (the
// occlusion test of Observation Fusion reads the surface depth at the observed Gaussians' centres only: 1.4 % of
// the pixels for a 42k-Gaussian model of a real capture, 30 % for 300k Gaussians in a synthetic box;
// docs/performance.md), bitwise what rasterize_forward gives at those pixels.
// A tile's chosen pixels are packed 8 to a vector in the order listed, whatever their rows (a pack is not a
// batch; tile_pixels lists them by quadrant). Each pack walks the tile's Gaussians front to back as a batch does
// in rasterize_forward: the same records, the same batch masks (batch_mask), a lane evaluated only where the mask
// bit of its own pixel's batch is set and the pixel still composites, alpha from the same operations (alpha_at:
// eval_gaussian with the pixel row per lane), the same cut-offs and sums. So every chosen pixel sees the same
// sequence of operations and gets the same bits (test_pixels.cpp, both compilations). A tile with m chosen
// pixels walks ceil(m / 8) packs instead of 32 batches; a tile with none costs nothing. The list is walked in
// chunks of 64 Gaussians (records gathered, masks made, then walked), so what lies behind the point where every
// pack has stopped is never read. No colour, final T or last contributor is kept.
#include "render/raster_isa.h"

#include <omp.h>

#include <algorithm>

#include "render/rasterize_common.h"

#pragma GCC diagnostic ignored "-Wpsabi"

#include "render/raster_isa_begin.h"
#include "render/rasterize_masks.h"  // inside the region: its kernels take the region's instruction sets

namespace hgs::render::HGS_RASTER_NS {
using namespace detail;
namespace {

constexpr int kMaxPacks = kTileSize * kTileSize / kLanes;  // 32: a tile's pixels, 8 to a pack
constexpr int kChunk = 64;                                 // Gaussians gathered and masked at a time

// eval_gaussian's alpha at 8 pixels anywhere in a tile (centres fx, fy per lane). The products and fused
// multiply-adds are spelt out: eval_gaussian's dy is one scalar per batch, so GCC fuses a * dx + b dy there as
// fma(a, dx, b dy) and dx (...) + c dy^2 as fma(dx, ..., c dy^2); with dy a vector it fuses b * dy instead, and
// the alphas differ in the last bit (test_pixels.cpp fails with the expression written as eval_gaussian's).
template <class T>
inline __attribute__((always_inline)) simd::Pack<T> alpha_at(const T* rc, simd::Pack<T> fx, simd::Pack<T> fy) {
  using P = simd::Pack<T>;
  const P dy = rc[kMy] - fy;
  const P dx = rc[kMx] - fx;
  const P bdy = rc[kB] * dy;
  const P hcdy2 = rc[kHc] * dy * dy;
  const P power = -simd::fmadd(dx, simd::fmadd(simd::splat(rc[kHa]), dx, bdy), hcdy2);
  const P araw = rc[kOp] * simd::vexp(power);
  return simd::vmin<T>(araw, simd::splat(T(kAlphaMax)));
}

// The packs of one tile: pixel centres, each lane's batch (bit index into a Gaussian's mask), the batches a
// pack's lanes lie in (cover), and the compositing state: T, the depth sum and the lanes still compositing.
template <class T>
struct Packs {
  simd::Pack<T> fx[kMaxPacks], fy[kMaxPacks], tr[kMaxPacks], dsum[kMaxPacks];
  simd::Mask<T> batch[kMaxPacks], act[kMaxPacks];
  uint32_t cover[kMaxPacks];
  int count = 0;
};

template <class T>
void depth_tile(const Binning& bins, const TilePixels& px, int tile, const T* records, T* alpha_out, T* depth_out) {
  using P = simd::Pack<T>;
  using M = simd::Mask<T>;
  using L = MaskLane<T>;
  const int p0 = px.start[tile], m = px.start[tile + 1] - p0;
  if (m == 0) return;
  const int W = bins.width;
  const auto [tx0, ty0] = tile_origin(bins, tile);
  Packs<T> pk;
  pk.count = (m + kLanes - 1) / kLanes;
  for (int j = 0; j < pk.count; ++j) {
    pk.cover[j] = 0;
    for (int l = 0; l < kLanes; ++l) {
      const int i = j * kLanes + l;
      const int p = i < m ? px.pixel[p0 + i] : px.pixel[p0];  // spare lanes repeat a pixel, inactive
      const int x = p % W, y = p / W;
      const int bt = (y - ty0) * kBatchesPerRow + (x - tx0) / kLanes;
      pk.fx[j][l] = T(x) + T(0.5);
      pk.fy[j][l] = T(y) + T(0.5);
      pk.batch[j][l] = L(bt);
      pk.act[j][l] = i < m ? L(-1) : L(0);
      pk.cover[j] |= 1u << bt;
    }
    pk.tr[j] = simd::splat(T(1));
    pk.dsum[j] = P{};
  }
  // The walk, kChunk Gaussians at a time: their records gathered and their batch masks made (as forward does for
  // the whole list), then walked; the tile's packs usually stop long before its list ends.
  const int s = bins.tile_start[tile], n = bins.tile_start[tile + 1] - s;
  const MaskTile geom(bins, tile);
  uint32_t alive = pk.count == kMaxPacks ? ~0u : (1u << pk.count) - 1;
  uint32_t tile_cover = 0;  // the batches of the chosen pixels
  for (int j = 0; j < pk.count; ++j) tile_cover |= pk.cover[j];
  alignas(64) T rec[kChunk * kRecord];
  uint32_t gmask[kChunk];
  for (int k0 = 0; k0 < n && alive; k0 += kChunk) {
    const int nc = std::min(kChunk, n - k0);
    for (int k = 0; k < nc; ++k) {
      std::memcpy(rec + size_t(k) * kRecord, records + size_t(bins.tile_gauss[s + k0 + k]) * kRecord,
                  sizeof(T) * kRecord);
    }
    for (int k = 0; k < nc; ++k) gmask[k] = batch_mask(rec + size_t(k) * kRecord, geom);
    for (int k = 0; k < nc && alive; ++k) {
      const uint32_t gm = gmask[k];
      if (!(gm & tile_cover)) continue;
      const T* rc = rec + size_t(k) * kRecord;
      const M gmv = M{} + L(gm);
      for (uint32_t live = alive; live; live &= live - 1) {
        const int j = __builtin_ctz(live);
        if (!(gm & pk.cover[j])) continue;
        const M in_mask = ((gmv >> pk.batch[j]) & L(1)) != L(0);  // the lane's own batch is in the mask
        const P alpha = alpha_at(rc, pk.fx[j], pk.fy[j]);
        M active = pk.act[j];
        const M valid = active & in_mask & (alpha >= T(kAlphaMin));
        if (!simd::any(valid)) continue;
        const P Tr = pk.tr[j];
        const P testT = Tr * (T(1) - alpha);
        const M stop = valid & (testT < T(kTransmittanceMin));
        active = active & ~stop;
        const M acc = valid & ~stop;
        const P wgt = acc ? alpha * Tr : P{};
        pk.dsum[j] += wgt * rc[kZ];
        pk.tr[j] = acc ? testT : Tr;
        pk.act[j] = active;
        if (!simd::any(active)) alive &= ~(1u << j);
      }
    }
  }
  for (int i = 0; i < m; ++i) {
    const int j = i / kLanes, l = i % kLanes;
    alpha_out[p0 + i] = T(1) - pk.tr[j][l];
    depth_out[p0 + i] = pk.dsum[j][l];
  }
}

}  // namespace

template <class T>
void rasterize_depth_at(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws, const TilePixels& px,
                        T* alpha, T* depth) {
  if (ws.records.size() < size_t(in.n) * kRecord) ws.records.resize(size_t(in.n) * kRecord);
  build_records(in, bins, ws.records.data());
  const T* R = ws.records.data();
  const int run = tile_run(bins.num_tiles);
#pragma omp parallel for schedule(dynamic, run)
  for (int t = 0; t < bins.num_tiles; ++t) depth_tile<T>(bins, px, t, R, alpha, depth);
}

template void rasterize_depth_at<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                        const TilePixels&, float*, float*);
template void rasterize_depth_at<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                         const TilePixels&, double*, double*);

}  // namespace hgs::render::HGS_RASTER_NS

#include "render/raster_isa_end.h"
