// Tile rasterizer, forward: per-pixel front-to-back alpha compositing (rasterize.h has the whole algorithm).
// Per Gaussian, one 16-scalar record (build_records) and a 32-bit mask of the 8-pixel batches of each tile its
// alpha >= 1/255 ellipse reaches (build_masks, exact per-row x-intervals). Each tile walks its Gaussians front to
// back (Gaussian-major) over the batches of their masks that still have a live pixel: alpha = min(kAlphaMax,
// opacity exp(power)), skipped below kAlphaMin, the pixel stops (without accumulating) when T (1 - alpha) <
// kTransmittanceMin, else w = alpha T is accumulated into colour / depth / pixel-weight sums. Extra channels and
// sparse groups are added in the walk (the folded path) or summed afterwards from each batch's recorded visits
// (composite_extras, composite_groups: many channels), in the same order either way; the groups are written
// interleaved per pixel or as one plane per group (RasterOutputs::group_planes; optionally only in the tiles where
// the group has Gaussians, flagged in group_live, the others +0 and left unwritten). Saves
// final T and the last contributor per pixel for backward; per-pair weight sums are reduced per Gaussian in a fixed
// order.
#include "render/raster_isa.h"

#include <omp.h>

#include <algorithm>
#include <cstring>
#include <tuple>

#include "render/rasterize_common.h"

#pragma GCC diagnostic ignored "-Wpsabi"

#include "render/raster_isa_begin.h"
#include "render/rasterize_masks.h"  // inside the region: its kernels take the region's instruction sets

namespace hgs::render::HGS_RASTER_NS {
using namespace detail;
namespace {

// Extra channels of one batch, forward: dst[c] = sum_v w_v extra_{g_v}[c] over the batch's visits in walk order
// (g_v the Gaussian's index, ex [N, XS] the input rows). The walk itself would read-modify-write every channel
// of the batch state per visit (bound by loads and stores); here a visit costs one weight load and one
// broadcast FMA per channel. The sums run in the same order as a per-visit accumulation: the same values.
template <class T>
void composite_extras(const int* vk, const simd::Pack<T>* vw, int cnt, const T* ex, int C, int XS, simd::Pack<T>* dst) {
  for_channel_chunks(C, [&]<int CH>(int c0) {
    simd::Pack<T> acc[CH];  // local, so the sums stay in registers
    weighted_rows<CH>(
        vw, cnt, [&](int v) { return ex + size_t(vk[v]) * XS; }, c0, acc);
    for (int i = 0; i < CH; ++i) dst[c0 + i] = acc[i];
  });
}

// Sparse groups of one batch, forward: dst[id_e * GW + i] += w_v val_e[i] for every entry e of every visit's
// Gaussian, visits in walk order (each group channel sums its contributions in the order of the walk). ptr [N+1],
// id [E], val [E, GW]; dst [G * GW] packs.
template <class T>
void composite_groups(const int* vk, const simd::Pack<T>* vw, int cnt, const RasterInputs<T>& in, simd::Pack<T>* dst) {
  for (int v = 0; v < cnt; ++v) add_group_values(in, in.group_ptr[vk[v]], in.group_ptr[vk[v] + 1], vw[v], dst);
}

// A tile's forward batch state in per-thread scratch: per batch BS packs [T, R, G, B, D, E[C], MW[J], GR[G * GW]]
// (the group channels at GO), the pixels still compositing (act) and each pixel's last contributor, 1-based
// (last).
enum { bT, bR, bG, bB, bD, kBatchFixed };
template <class T>
struct ForwardBatches {
  simd::Pack<T>* st;    // [kBatches, BS]
  simd::Mask<T>* act;   // [kBatches]
  simd::Mask<T>* last;  // [kBatches]
  int C, J, BS, GO;     // extra channels, pixel-weight maps, state stride, offset of the group channels
};

// The visit lists of the visit-list path: batch bt's visits (Gaussian index, weight pack) are entries
// [off[bt], off[bt] + cnt[bt]) of vk and vw, in walk order.
template <class T>
struct ForwardVisits {
  const int* off;  // [kBatches + 1]
  int* cnt;        // [kBatches]
  int* vk;
  simd::Pack<T>* vw;
};

// Starts the batches of the tile at (tx0, ty0): T = 1, sums zero, the pixel-weight maps loaded (jmask [kBatches]:
// the maps present in each batch), the pixels inside the image active. Returns the batches inside the image.
template <class T>
inline __attribute__((always_inline)) uint32_t start_forward_batches(const RasterInputs<T>& in, const Binning& bins,
                                                                     int tx0, int ty0, const ForwardBatches<T>& b,
                                                                     uint32_t* jmask) {
  using P = simd::Pack<T>;
  using M = simd::Mask<T>;
  const int W = bins.width, H = bins.height, C = b.C, J = b.J;
  const M lane_i = __builtin_convertvector(simd::iota_pack<T>(), M);
  uint32_t alive = 0;
  for (int bt = 0; bt < kBatches; ++bt) {
    jmask[bt] = 0;
    const int py = ty0 + bt / kBatchesPerRow, px0 = tx0 + (bt % kBatchesPerRow) * kLanes;
    if (py >= H || px0 >= W) continue;
    const int nvalid = std::min(kLanes, W - px0);
    alive |= 1u << bt;
    P* st = b.st + size_t(bt) * b.BS;
    st[bT] = simd::splat(T(1));
    for (int f = bR; f < b.BS; ++f) st[f] = P{};
    if (J > 0) jmask[bt] = load_batch_maps(in, J, W, H, py, px0, nvalid, st + kBatchFixed + C);
    b.act[bt] = lane_i < MaskLane<T>(nvalid);
    b.last[bt] = M{};
  }
  return alive;
}

// Composites Gaussian k of the tile (record rc, input index gi, folded channels fg) into the batches mb of its
// mask that are still alive: alpha below kAlphaMin is skipped, a pixel whose T (1 - alpha) would fall below
// kTransmittanceMin stops without accumulating, else w = alpha T is added to the sums (colour, depth, folded
// channels, wa [J] the Gaussian's pixel-weight sums) or recorded in the batch's visit list, and T *= 1 - alpha.
// A batch whose pixels have all stopped leaves `alive`.
template <class T, bool kDepth, int kX>
inline __attribute__((always_inline)) void forward_gaussian(const RasterInputs<T>& in, const T* rc, int k, int gi,
                                                            const FoldedGaussian<T, 4>& fg, const ForwardBatches<T>& b,
                                                            const uint32_t* jmask, int tx0, int ty0, uint32_t mb,
                                                            uint32_t& alive, simd::Pack<T>* wa, uint32_t& used,
                                                            const ForwardVisits<T>& vl) {
  using P = simd::Pack<T>;
  using M = simd::Mask<T>;
  const int C = b.C, J = b.J, GO = b.GO;
  const M kk = M{} + MaskLane<T>(k + 1);
  while (mb) {
    const int bt = __builtin_ctz(mb);
    mb &= mb - 1;
    P* st = b.st + size_t(bt) * b.BS;
    const GaussianAtBatch<T> ev = eval_gaussian(rc, tx0, ty0, bt);
    M active = b.act[bt];
    const M valid = active & (ev.alpha >= T(kAlphaMin));
    if (!simd::any(valid)) continue;
    const P Tr = st[bT];
    const P testT = Tr * (T(1) - ev.alpha);
    const M stop = valid & (testT < T(kTransmittanceMin));
    active = active & ~stop;
    const M acc = valid & ~stop;
    const P wgt = acc ? ev.alpha * Tr : P{};
    st[bR] += wgt * rc[kCr];
    st[bG] += wgt * rc[kCg];
    st[bB] += wgt * rc[kCb];
    if (kDepth) st[bD] += wgt * rc[kZ];
    if constexpr (kX == kVisitLists) {
      const int v = vl.off[bt] + vl.cnt[bt]++;
      vl.vk[v] = gi;
      vl.vw[v] = wgt;
    }
    if constexpr (kX == kFolded) {  // the sums of composite_extras / composite_groups, in the same order
      for (int c = 0; c < C; ++c) st[kBatchFixed + c] += wgt * fg.x[c];
      if (fg.one) {
        P* d = st + GO + fg.slot;
        for (int i = 0; i < 4; ++i) d[i] += wgt * fg.v[i];
      } else {
        add_group_values(in, fg.e0, fg.e0 + fg.ne, wgt, st + GO);
      }
    }
    for_batch_maps(jmask[bt], J, [&](int jj) { wa[jj] += wgt * st[kBatchFixed + C + jj]; });
    used |= jmask[bt];
    st[bT] = acc ? testT : Tr;
    b.last[bt] = acc ? kk : b.last[bt];
    b.act[bt] = active;
    if (!simd::any(active)) alive &= ~(1u << bt);
  }
}

// Writes the tile's pixels out (batches all_batches): the visit-list path's extra channels and groups summed
// first, then colour over the background, alpha, final T, last contributor, depth, extra and group channels.
// With group planes, the planes of groups [0, ng) of glist only (glist null: every group).
template <class T, bool kDepth, int kX>
inline __attribute__((always_inline)) void write_forward_batches(const RasterInputs<T>& in, const Binning& bins,
                                                                 int tx0, int ty0, uint32_t all_batches,
                                                                 const ForwardBatches<T>& b, const ForwardVisits<T>& vl,
                                                                 const int* glist, int ng,
                                                                 const RasterOutputs<T>& out) {
  using P = simd::Pack<T>;
  const int W = bins.width, C = b.C, GT = b.BS - b.GO, GO = b.GO;
  const int XS = in.extra_stride > 0 ? in.extra_stride : C;
  const T bg0 = in.background[0], bg1 = in.background[1], bg2 = in.background[2];
  for (int bt = 0; bt < kBatches; ++bt) {
    if (!((all_batches >> bt) & 1)) continue;
    const int py = ty0 + bt / kBatchesPerRow, px0 = tx0 + (bt % kBatchesPerRow) * kLanes;
    const int nvalid = std::min(kLanes, W - px0);
    P* st = b.st + size_t(bt) * b.BS;
    if (kX == kVisitLists && vl.cnt[bt] > 0) {
      const int* vk = vl.vk + vl.off[bt];
      const P* vw = vl.vw + vl.off[bt];
      if (C > 0) composite_extras<T>(vk, vw, vl.cnt[bt], in.extra, C, XS, st + kBatchFixed);
      if (GT > 0) composite_groups<T>(vk, vw, vl.cnt[bt], in, st + GO);
    }
    for (int l = 0; l < nvalid; ++l) {
      const size_t p = size_t(py) * W + px0 + l;
      const T Tr = st[bT][l];
      out.rgb[3 * p] = st[bR][l] + Tr * bg0;
      out.rgb[3 * p + 1] = st[bG][l] + Tr * bg1;
      out.rgb[3 * p + 2] = st[bB][l] + Tr * bg2;
      out.alpha[p] = T(1) - Tr;
      out.final_T[p] = Tr;
      out.last[p] = int32_t(b.last[bt][l]);
      if (kDepth) out.depth[p] = st[bD][l];
      if (kX != kNoChannels)
        for (int c = 0; c < C; ++c) out.extra[p * C + c] = st[kBatchFixed + c][l];
      if (kX != kNoChannels && !out.group_planes)
        for (int c = 0; c < GT; ++c) out.groups[p * GT + c] = st[GO + c][l];
    }
    if (kX != kNoChannels && out.group_planes && GT > 0) {  // group g's plane: the batch's pixels contiguous
      const int GW = in.group_width;
      const size_t P = size_t(W) * bins.height, p0 = size_t(py) * W + px0;
      for (int q = 0; q < ng; ++q) {
        const int g = glist ? glist[q] : q;
        T* o = out.groups + (size_t(g) * P + p0) * GW;
        for (int l = 0; l < nvalid; ++l)
          for (int i = 0; i < GW; ++i) o[size_t(l) * GW + i] = st[GO + g * GW + i][l];
      }
    }
  }
}

// Gaussian k's pixel-weight sums once its walk is done: o [J] gets the lane sums of wa [J] of the maps it added to
// (used: the maps present in the batches it reached; more than 32 maps: every map), the others are left unwritten
// (their sums would be +0: the reduction skips them), and wa goes back to zero for the next Gaussian.
template <class T>
inline void gaussian_weights(int J, uint32_t used, simd::Pack<T>* wa, T* o) {
  for_batch_maps(used, J, [&](int jj) { o[jj] = simd::hsum<T>(wa[jj]), wa[jj] = simd::Pack<T>{}; });
}

// The tile's per-pair pixel-weight sums, pair_w [pairs, J] and pair_maps [pairs], from the tile's own tw [n, J]
// and tu [n] (gaussian_weights' rows and maps). Written after the walk, not as each Gaussian ends: a pair's row is
// a cache line the walk would wait on.
template <class T>
void store_pair_weights(const Binning& bins, int tile, int n, int J, const T* tw, const uint32_t* tu, T* pair_w,
                        uint32_t* pair_maps) {
  const int s = bins.tile_start[tile];
  for (int k = 0; k < n; ++k) {
    const size_t p = size_t(bins.tile_pair[s + k]);
    T* o = pair_w + p * J;
    const T* t = tw + size_t(k) * J;
    if (J <= 32) pair_maps[p] = tu[k];
    for_batch_maps(tu[k], J, [&](int jj) { o[jj] = t[jj]; });
  }
}

// Forward of one tile, Gaussian-major: the tile's Gaussians are walked front to back; each updates the batches
// its mask names that still have a live pixel (per-batch accumulators in per-thread scratch); a batch drops out
// when all its pixels hit the transmittance cut-off, the tile ends when no batch is left. live_row [G]: where the
// tile's group_live flags go (null: planes written everywhere, no flags).
template <class T, bool kDepth, int kX>
void forward_tile(const RasterInputs<T>& in, const Binning& bins, int tile, typename RasterWorkspace<T>::PerThread& w,
                  const T* records, const T* chan, T* tile_records, uint32_t* ws_masks, T* pair_w, uint32_t* pair_maps,
                  uint8_t* live_row, const RasterOutputs<T>& out) {
  using P = simd::Pack<T>;
  using M = simd::Mask<T>;
  const int C = in.num_extra, J = in.num_weights;
  const int GT = in.num_groups * in.group_width;  // group channels, after the pixel-weight maps in the state
  const auto [tx0, ty0] = tile_origin(bins, tile);
  TileData<T> td;
  const bool any_g = load_records(bins, records, tile_records, true, tile, td);
  const int n = any_g ? td.n : 0, s = bins.tile_start[tile];
  const int* gauss = bins.tile_gauss.data() + s;  // [n] the tile's Gaussians
  uint32_t* masks = ws_masks + s;
  if (any_g) build_masks(bins, tile, td, masks);
  ForwardBatches<T> b{nullptr, nullptr, nullptr, C, J, kBatchFixed + C + J + GT, kBatchFixed + C + J};
  b.st = w.bstate.template get<P>(size_t(kBatches) * b.BS);
  b.act = w.blast.template get<M>(size_t(2) * kBatches);
  b.last = b.act + kBatches;
  // The walked Gaussian's pixel-weight sums (packs, zero between Gaussians), and the tile's Gaussians' lane sums
  // and maps (tw [n, J], tu [n]: the maps each added to; more than 32 maps: every row whole, zero where unwalked).
  P* wa = J > 0 ? w.wacc.template get<P>(size_t(J)) : nullptr;  // [J]
  for (int jj = 0; jj < J; ++jj) wa[jj] = P{};
  T* tw = J > 0 ? w.tile_w.template get<T>(size_t(n) * J) : nullptr;
  uint32_t* tu = J > 0 ? w.tile_maps.template get<uint32_t>(size_t(n)) : nullptr;
  auto gaussian_done = [&](int k, uint32_t used) {
    tu[k] = used;
    gaussian_weights<T>(J, used, wa, tw + size_t(k) * J);
  };
  uint32_t jmask[kBatches];  // pixel-weight maps present in each batch (for_batch_maps)
  uint32_t alive = start_forward_batches(in, bins, tx0, ty0, b, jmask);
  const uint32_t all_batches = alive;
  int voff[kBatches + 1], vcnt[kBatches] = {};
  ForwardVisits<T> vl{voff, vcnt, nullptr, nullptr};
  if (kX == kVisitLists && n > 0) std::tie(vl.vk, vl.vw) = size_visit_lists<P>(w, masks, n, all_batches, voff);
  int kend = 0;  // Gaussians [kend, n) were never reached (all batches terminated)
  for (int k = 0; k < n && alive; ++k) {
    kend = k + 1;
    if (kX == kFolded && k + kChanAhead < n) prefetch_chan_record(chan, gauss[k + kChanAhead]);
    const uint32_t mb = masks[k] & alive;
    if (!mb) {
      if (J > 0) gaussian_done(k, 0);
      continue;
    }
    const T* rc = td.rec + size_t(k) * kRecord;
    FoldedGaussian<T, 4> fg;
    const T* cr = kX == kFolded ? chan + size_t(gauss[k]) * kChanRecord : nullptr;
    load_folded<T, 4>(rc, cr, kX == kFolded ? C : 0, kX == kFolded && GT > 0, in.group_width, fg);
    const int gi = kX == kVisitLists ? gauss[k] : 0;
    uint32_t used = 0;
    forward_gaussian<T, kDepth, kX>(in, rc, k, gi, fg, b, jmask, tx0, ty0, mb, alive, wa, used, vl);
    if (J > 0) gaussian_done(k, used);
  }
  if (J > 0)  // never reached (every batch had stopped)
    for (int k = kend; k < n; ++k) gaussian_done(k, 0);
  // Planes written only where their group has Gaussians (out.group_live): the others' values here are +0, the
  // state they were never added to.
  int ng = in.num_groups;
  const int* glist = nullptr;
  if (kX != kNoChannels && live_row) {  // out.group_live with groups (an empty tile has td.n = 0: no groups)
    const TileGroupList tg = tile_group_list(in, td, gauss, kX == kFolded ? chan : nullptr, w.groups);
    glist = tg.list;
    ng = tg.count;
    std::memcpy(live_row, tg.used, size_t(in.num_groups));  // the tile's own line (out.group_live after the walks)
  }
  write_forward_batches<T, kDepth, kX>(in, bins, tx0, ty0, all_batches, b, vl, glist, ng, out);
  if (J > 0) store_pair_weights<T>(bins, tile, n, J, tw, tu, pair_w, pair_maps);
}

}  // namespace

template <class T>
void rasterize_forward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws,
                       const RasterOutputs<T>& out) {
  ensure_threads(ws);
  const bool dep = in.depth != nullptr;
  const int x = channel_path(in, in.num_extra, in.num_groups * in.group_width, 0);
  if (ws.masks.size() < size_t(bins.num_pairs)) ws.masks.resize(size_t(bins.num_pairs));
  uint32_t* MK = ws.masks.data();
  if (ws.records.size() < size_t(in.n) * kRecord) ws.records.resize(size_t(in.n) * kRecord);
  build_records(in, bins, ws.records.data());
  const T* R = ws.records.data();
  if (ws.tile_records.size() < size_t(bins.num_pairs) * kRecord)
    ws.tile_records.resize(size_t(bins.num_pairs) * kRecord);
  T* TR = ws.tile_records.data();
  ws.chan_n = -1;
  const T* CR = x == kFolded ? fill_chan_records(in, ws) : nullptr;  // the folded walk's, reused by backward
  // The live flags, written per tile into a line of its own and gathered into out.group_live [G, tiles] after the
  // walks: written in place, the threads' neighbouring tiles wrote the same G cache lines.
  const int G = in.num_groups, LS = (G + 63) / 64 * 64;
  const bool live = out.group_live && G > 0 && in.group_width > 0 && x != kNoChannels;
  if (live && ws.live_rows.size() < size_t(bins.num_tiles) * LS) ws.live_rows.resize(size_t(bins.num_tiles) * LS);
  uint8_t* LR = ws.live_rows.data();
  const int J = in.num_weights;
  if (J > 0 && ws.pair_w.size() < size_t(bins.num_pairs) * J) ws.pair_w.resize(size_t(bins.num_pairs) * J);
  if (J > 0 && J <= 32 && ws.pair_maps.size() < size_t(bins.num_pairs)) ws.pair_maps.resize(size_t(bins.num_pairs));
  T* PW = ws.pair_w.data();
  uint32_t* PM = ws.pair_maps.data();
  const int run = tile_run(bins.num_tiles);
#pragma omp parallel
  {
    auto& w = ws.threads[omp_get_thread_num()];
#pragma omp for schedule(dynamic, run)
    for (int t = 0; t < bins.num_tiles; ++t) {
      uint8_t* lr = live ? LR + size_t(t) * LS : nullptr;
      if (dep && x == kVisitLists) forward_tile<T, true, kVisitLists>(in, bins, t, w, R, CR, TR, MK, PW, PM, lr, out);
      else if (dep && x == kFolded) forward_tile<T, true, kFolded>(in, bins, t, w, R, CR, TR, MK, PW, PM, lr, out);
      else if (dep) forward_tile<T, true, kNoChannels>(in, bins, t, w, R, CR, TR, MK, PW, PM, lr, out);
      else if (x == kVisitLists) forward_tile<T, false, kVisitLists>(in, bins, t, w, R, CR, TR, MK, PW, PM, lr, out);
      else if (x == kFolded) forward_tile<T, false, kFolded>(in, bins, t, w, R, CR, TR, MK, PW, PM, lr, out);
      else forward_tile<T, false, kNoChannels>(in, bins, t, w, R, CR, TR, MK, PW, PM, lr, out);
    }
    if (live) {
#pragma omp for schedule(static)
      for (int g = 0; g < G; ++g)
        for (int t = 0; t < bins.num_tiles; ++t)
          out.group_live[size_t(g) * bins.num_tiles + t] = LR[size_t(t) * LS + g];
    }
    if (J > 0) {
#pragma omp for schedule(static)
      for (int i = 0; i < in.n; ++i) {
        T* o = out.weight_sums + size_t(i) * J;
        for (int jj = 0; jj < J; ++jj) o[jj] = 0;
        // Each map's sum over the pairs in pair order; a map a pair did not add to is +0 there, which leaves a
        // sum that starts at +0 unchanged (such a sum is never -0), so only the maps of pair_maps are added.
        for (int p = bins.pair_offset[i]; p < bins.pair_offset[i + 1]; ++p) {
          const T* pw = PW + size_t(p) * J;
          for_batch_maps(J <= 32 ? PM[p] : 0u, J, [&](int jj) { o[jj] += pw[jj]; });
        }
      }
    }
  }
}

template void rasterize_forward<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                       const RasterOutputs<float>&);
template void rasterize_forward<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                        const RasterOutputs<double>&);

}  // namespace hgs::render::HGS_RASTER_NS

#include "render/raster_isa_end.h"
