// Internals shared by the tile rasterizer's forward (rasterize_forward.cpp) and backward
// (rasterize_backward.cpp) kernels: the pixel batches of a tile, the 16-scalar Gaussian record layout, the copy
// of a tile's records into scratch, the evaluation of a Gaussian at a batch of pixels (written once for both),
// a Gaussian's folded channels and their per-Gaussian channel record, per-batch visit lists, pixel-weight map and
// channel-chunk iteration. The algorithm and the cut-offs (kAlphaMax, kAlphaMin, kTransmittanceMin) are described
// in rasterize.h.
#pragma once
#include <omp.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <type_traits>
#include <utility>

#include "render/rasterize.h"
#include "render/simd.h"

namespace hgs::render::HGS_RASTER_NS::detail {

using simd::kLanes;
constexpr int kBatchesPerRow = kTileSize / kLanes;
constexpr int kBatches = kTileSize * kBatchesPerRow;  // 32 batches of 8 pixels per tile

// Gaussian records: one 16-scalar record per Gaussian (one cache line for float), built once per forward in index
// order and copied per tile into contiguous per-thread scratch (the inner loops read them with broadcasts).
// kE0, kNe: the Gaussian's first group entry and its number of entries (int bits, record_int), so the walks find a
// Gaussian's groups in its tile record instead of in the [N + 1] group_ptr array (a cache miss per (tile,
// Gaussian) pair at a few hundred thousand Gaussians).
enum Field { kMx, kMy, kHa, kB, kHc, kA, kC, kOp, kCr, kCg, kCb, kZ, kMahal, kEy, kE0, kNe, kRecord = 16 };

template <class T>
inline void set_record_int(T& slot, int32_t v) {
  slot = T(0);
  std::memcpy(&slot, &v, sizeof v);
}
template <class T>
inline int32_t record_int(const T& slot) {
  int32_t v;
  std::memcpy(&v, &slot, sizeof v);
  return v;
}

// Every Gaussian's 16-scalar record, records [N, 16], from the inputs and the binning's Mahalanobis radii (the
// forward kernels build them once per call, in index order).
template <class T>
void build_records(const RasterInputs<T>& in, const Binning& bins, T* records) {
#pragma omp parallel for schedule(static)
  for (int g = 0; g < in.n; ++g) {
    T* r = records + size_t(g) * kRecord;
    r[kMx] = in.mean2d[2 * g];
    r[kMy] = in.mean2d[2 * g + 1];
    const T a = in.conic[3 * g], b = in.conic[3 * g + 1], c = in.conic[3 * g + 2];
    r[kHa] = T(0.5) * a;
    r[kB] = b;
    r[kHc] = T(0.5) * c;
    r[kA] = a;
    r[kC] = c;
    r[kOp] = in.opacity[g];
    r[kCr] = in.color[3 * g];
    r[kCg] = in.color[3 * g + 1];
    r[kCb] = in.color[3 * g + 2];
    r[kZ] = in.depth ? in.depth[g] : T(0);
    const double m = bins.mahal[g];
    r[kMahal] = T(m);
    const double det = double(a) * double(c) - double(b) * double(b);
    r[kEy] = m > 0 && det > 0 ? T(std::sqrt(m * double(a) / det) + 1e-3) : T(-1);
    if (in.num_groups > 0 && in.group_ptr) {
      set_record_int(r[kE0], in.group_ptr[g]);
      set_record_int(r[kNe], in.group_ptr[g + 1] - in.group_ptr[g]);
    } else {
      r[kE0] = r[kNe] = 0;
    }
  }
}

// Channel records (ChannelPath kFolded): per Gaussian 16 scalars (one cache line for float) built by forward in
// index order beside the records and reused by backward, chan [N, 16]: the first C <= 4 extra values (kCx), and
// when the Gaussian has exactly one group entry its group id (kCid, int bits; -1 otherwise) and the entry's first
// min(4, group width) values (kCv). A walk reads one line per (tile, Gaussian) pair for what were three scattered
// reads (the extra row, group_id and group_val: in the hybrid step's tiles, a cache miss each).
enum ChanField { kCx = 0, kCv = 4, kCid = 8, kChanRecord = 16 };
// The forward walk fetches the channel record of the Gaussian kChanAhead places further in its order while it works
// on one (its line is a cache miss: a tile's Gaussians are in depth order, not index order; perf put a quarter of
// forward_tile's time on that load). The backward's tile_group_list pass touches the records first, and a
// prefetch in its walk measured neutral (docs/performance.md, session seven).
constexpr int kChanAhead = 8;
template <class T>
inline void prefetch_chan_record(const T* chan, int gaussian) {
  const char* p = reinterpret_cast<const char*>(chan + size_t(gaussian) * kChanRecord);
  for (size_t b = 0; b < sizeof(T) * kChanRecord; b += 64) __builtin_prefetch(p + b);
}
template <class T>
void build_chan_records(const RasterInputs<T>& in, int C, int XS, bool groups, T* chan) {
  const int GV = std::min(in.group_width, 4);
#pragma omp parallel for schedule(static)
  for (int g = 0; g < in.n; ++g) {
    T* r = chan + size_t(g) * kChanRecord;
    for (int c = 0; c < kChanRecord; ++c) r[c] = T(0);
    for (int c = 0; c < C; ++c) r[kCx + c] = in.extra[size_t(g) * XS + c];
    const bool one = groups && in.group_ptr[g + 1] - in.group_ptr[g] == 1;
    set_record_int(r[kCid], one ? in.group_id[in.group_ptr[g]] : -1);
    if (one)
      for (int i = 0; i < GV; ++i) r[kCv + i] = in.group_val[size_t(in.group_ptr[g]) * in.group_width + i];
  }
}

// Builds the channel records of in (its C = num_extra values, rows of stride extra_stride, and its groups) into
// ws.chan_records and marks them as in's (ws.chan_n). Returns them.
template <class T>
const T* fill_chan_records(const RasterInputs<T>& in, RasterWorkspace<T>& ws) {
  const int C = in.num_extra, XS = in.extra_stride > 0 ? in.extra_stride : C;
  if (ws.chan_records.size() < size_t(in.n) * kChanRecord) ws.chan_records.resize(size_t(in.n) * kChanRecord);
  build_chan_records(in, C, XS, in.num_groups > 0 && in.group_width > 0 && in.group_ptr, ws.chan_records.data());
  ws.chan_n = in.n;
  return ws.chan_records.data();
}

template <class T>
struct TileData {
  int n = 0;
  const T* rec = nullptr;  // [n, 16]
};

// Copies the tile's records into per-thread scratch. Returns false for an empty tile. (Extra channels are read
// in place: a Gaussian's C values are one contiguous row of the input.)
template <class T>
bool load_records(const Binning& bins, const T* records, T* tile_records, bool gather, int tile, TileData<T>& td) {
  const int s = bins.tile_start[tile], e = bins.tile_start[tile + 1];
  const int n = e - s;
  td.n = n;
  if (n == 0) return false;
  T* rec = tile_records + size_t(s) * kRecord;  // [n, 16], written by forward, read again by backward
  td.rec = rec;
  if (gather)
    for (int k = 0; k < n; ++k)
      std::memcpy(rec + size_t(k) * kRecord, records + size_t(bins.tile_gauss[s + k]) * kRecord, sizeof(T) * kRecord);
  return true;
}

// The channel groups a tile's Gaussians have entries in (from their records' kE0 / kNe), ascending: list [G] gets
// them, the count is returned (used [G] is scratch). No Gaussian of the tile reads another group's upstream
// gradient, so backward loads these groups' only. (The hybrid method's object groups: a tile sees one or two of
// the view's objects, and each pixel's row holds the gradients of all of them.) Forward writes every group's
// zeros (writing them apart from the state is slower than the plain copy) unless its output flags the tiles it
// wrote (RasterOutputs::group_live): then these groups' planes only.
template <class T>
int tile_groups(const RasterInputs<T>& in, const TileData<T>& td, const int* gauss, const T* chan, uint8_t* used,
                int* list) {
  const int G = in.num_groups;
  std::memset(used, 0, size_t(G));
  for (int k = 0; k < td.n; ++k) {
    const T* r = td.rec + size_t(k) * kRecord;
    const int e0 = record_int(r[kE0]), e1 = e0 + record_int(r[kNe]);
    if (chan && e1 - e0 == 1) {  // the id in the Gaussian's channel record, the line its walk reads
      used[record_int(chan[size_t(gauss[k]) * kChanRecord + kCid])] = 1;
      continue;
    }
    for (int e = e0; e < e1; ++e) used[in.group_id[e]] = 1;
  }
  int m = 0;
  for (int g = 0; g < G; ++g)
    if (used[g]) list[m++] = g;
  return m;
}

// tile_groups in a thread's scratch (w.groups: the list [G] ints, then the flags [G] bytes); gauss [n] the tile's
// Gaussians (bins.tile_gauss from the tile's start), chan their channel records or null.
struct TileGroupList {
  const int* list;      // [count] the tile's groups, ascending
  const uint8_t* used;  // [G] 1 for the groups in the list
  int count;
};
template <class T>
TileGroupList tile_group_list(const RasterInputs<T>& in, const TileData<T>& td, const int* gauss, const T* chan,
                              RasterScratch& scratch) {
  int* list = scratch.template get<int>(size_t(2) * in.num_groups);
  uint8_t* used = reinterpret_cast<uint8_t*>(list + in.num_groups);
  return {list, used, tile_groups(in, td, gauss, chan, used, list)};
}

// Per-batch visit lists of a tile in the thread's scratch (w.vk, w.vw): offsets [33] into one flat
// array sized by the bits `batches` of the masks of Gaussians [0, n) (an upper bound on the visits of every
// batch). Returns the visit arrays: Gaussian indices and packs.
template <class P, class PerThread>
std::pair<int*, P*> size_visit_lists(PerThread& w, const uint32_t* masks, int n, uint32_t batches, int* off) {
  int cnt[kBatches] = {};
  for (int k = 0; k < n; ++k)
    for (uint32_t mb = masks[k] & batches; mb; mb &= mb - 1) ++cnt[__builtin_ctz(mb)];
  off[0] = 0;
  for (int b = 0; b < kBatches; ++b) off[b + 1] = off[b] + cnt[b];
  const size_t nv = size_t(off[kBatches]);
  return {w.vk.template get<int>(nv), w.vw.template get<P>(nv)};
}

// Map j of the planar pixel-weight maps [J, H, W] at the batch's pixels [px0, px0 + nvalid) of row py, as a pack
// (lanes past nvalid 0): one load for a whole batch of float maps.
template <class T>
inline __attribute__((always_inline)) simd::Pack<T> load_weight_map(const float* maps, int W, int H, int j, int py,
                                                                    int px0, int nvalid) {
  const float* src = maps + (size_t(j) * H + py) * W + px0;
  simd::Pack<T> v{};
  if constexpr (std::is_same_v<T, float>) {
    if (nvalid == kLanes) {
      std::memcpy(&v, src, sizeof(v));
      return v;
    }
  }
  for (int l = 0; l < nvalid; ++l) v[l] = T(src[l]);
  return v;
}

// Pixel-weight maps of a batch: bit j of `present` is set when map j is non-zero at one of its pixels
// (map_bit), and f(j) runs for those maps only (for every map when there are more than 32).
inline uint32_t map_bit(int j, bool nonzero) { return nonzero && j < 32 ? 1u << j : 0u; }
template <class F>
inline __attribute__((always_inline)) void for_batch_maps(uint32_t present, int J, F&& f) {
  if (J > 32) {
    for (int j = 0; j < J; ++j) f(j);
    return;
  }
  for (; present; present &= present - 1) f(__builtin_ctz(present));
}

// Runs chunk.template operator()<CH>(c0) over channels [0, C) in register-sized chunks of 12, 4 and 1.
template <class Chunk>
inline __attribute__((always_inline)) void for_channel_chunks(int C, Chunk&& chunk) {
  int c0 = 0;
  for (; c0 + 12 <= C; c0 += 12) chunk.template operator()<12>(c0);
  for (; c0 + 4 <= C; c0 += 4) chunk.template operator()<4>(c0);
  for (; c0 < C; ++c0) chunk.template operator()<1>(c0);
}

// acc[i] = sum_v w_v * row(v)[c0 + i], i < CH, over a visit list in order, the CH sums in registers. row(v) gives
// scalars (broadcast to the lanes) or packs (lane by lane).
template <int CH, class P, class Row>
inline __attribute__((always_inline)) void weighted_rows(const P* vw, int cnt, Row&& row, int c0, P* acc) {
  for (int i = 0; i < CH; ++i) acc[i] = P{};
  for (int v = 0; v < cnt; ++v) {
    const P wv = vw[v];
    const auto* r = row(v) + c0;
    for (int i = 0; i < CH; ++i) acc[i] += wv * r[i];
  }
}

// How a call's extra channels and groups are composited and differentiated (rasterize.h): not at all, from
// per-batch visit lists after the walk, or folded into the walk's own visit loop. ChannelPath::kAuto folds at
// most kFoldMaxChannels dense channels and group gradients of width at most kFoldMaxWidth, with any number of
// entries per Gaussian (the folded backward keeps the gradient sums of up to kFoldMaxEntries entries on the stack
// and takes a Gaussian with more from its own visit list); kFolded folds where allowed, kVisitLists never folds.
enum ChannelPathKernel { kNoChannels = 0, kVisitLists = 1, kFolded = 2 };
constexpr int kFoldMaxChannels = 4, kFoldMaxEntries = 4, kFoldMaxWidth = 4;
template <class T>
int channel_path(const RasterInputs<T>& in, int C, int GT, int grad_width) {
  if (C <= 0 && GT <= 0) return kNoChannels;
  const bool foldable = C <= kFoldMaxChannels && grad_width <= kFoldMaxWidth;
  return in.channel_path == ChannelPath::kVisitLists || !foldable ? kVisitLists : kFolded;
}

// One visit's group values: dst[id_e * GW + i] += w val_e[i] for the Gaussian's entries [e0, e1), dst [G * GW] a
// batch's group packs (forward; the visit-list path's composite_groups and the folded walk both call this).
template <class T>
inline __attribute__((always_inline)) void add_group_values(const RasterInputs<T>& in, int e0, int e1, simd::Pack<T> w,
                                                            simd::Pack<T>* dst) {
  const int GW = in.group_width;
  for (int e = e0; e < e1; ++e) {
    simd::Pack<T>* d = dst + size_t(in.group_id[e]) * GW;
    const T* x = in.group_val + size_t(e) * GW;
    for (int i = 0; i < GW; ++i) d[i] += w * x[i];
  }
}

// The integer type of a mask lane (the lane-index compares of the tile kernels).
template <class T>
using MaskLane = std::remove_reference_t<decltype(simd::Mask<T>{}[0])>;

// The batch's J pixel-weight maps (the batch's pixels [px0, px0 + nvalid) of row py) into dst [J] packs, lanes past
// nvalid 0, and the maps present (map_bit) returned: from the float maps, or, given a label image
// (in.pixel_labels [H, W]), M_j = 1 where the label is in.label_ids[j] and 0 elsewhere: the float maps' values
// for hard masks without their J floats per pixel (one 16-byte load per batch instead of J 32-byte ones).
template <class T>
inline __attribute__((always_inline)) uint32_t load_batch_maps(const RasterInputs<T>& in, int J, int W, int H, int py,
                                                               int px0, int nvalid, simd::Pack<T>* dst) {
  using P = simd::Pack<T>;
  uint32_t present = 0;
  if (!in.pixel_labels) {
    for (int jj = 0; jj < J; ++jj) {
      dst[jj] = load_weight_map<T>(in.pixel_weights, W, H, jj, py, px0, nvalid);
      present |= map_bit(jj, simd::any(dst[jj] != P{}));
    }
    return present;
  }
  using I = MaskLane<T>;
  simd::Mask<T> lab{};
  const uint16_t* src = in.pixel_labels + size_t(py) * W + px0;
  for (int l = 0; l < kLanes; ++l) lab[l] = l < nvalid ? I(src[l]) : I(-1);  // -1: no label id matches
  for (int jj = 0; jj < J; ++jj) {
    const simd::Mask<T> hit = lab == I(in.label_ids[jj]);
    dst[jj] = hit ? simd::splat(T(1)) : P{};
    present |= map_bit(jj, simd::any(hit));
  }
  return present;
}

// The first pixel of a tile (x, y).
inline std::pair<int, int> tile_origin(const Binning& bins, int tile) {
  return {(tile % bins.tiles_x) * kTileSize, (tile / bins.tiles_x) * kTileSize};
}

// One Gaussian at the 8 pixel centres of batch bt of the tile at (tx0, ty0), d = mean - pixel centre:
// power = -(a dx^2 / 2 + b dx dy + c dy^2 / 2), alpha = min(kAlphaMax, opacity exp(power)) (rasterize.h).
// Forward and backward both evaluate it here, so backward replays forward's alphas exactly; backward also
// reads d, b dy and the unclamped opacity exp(power) for the gradient (forward's compilation drops them).
template <class T>
struct GaussianAtBatch {
  simd::Pack<T> dx;     // mean x - pixel centre x, per pixel
  T dy, bdy;            // mean y - pixel centre y (one row), b dy
  simd::Pack<T> gauss;  // exp(power)
  simd::Pack<T> araw;   // opacity exp(power)
  simd::Pack<T> alpha;  // min(araw, kAlphaMax)
};
template <class T>
inline __attribute__((always_inline)) GaussianAtBatch<T> eval_gaussian(const T* rc, int tx0, int ty0, int bt) {
  GaussianAtBatch<T> e;
  const T fy = T(ty0 + bt / kBatchesPerRow) + T(0.5);
  const simd::Pack<T> fx = simd::iota_pack<T>() + (T(tx0 + (bt % kBatchesPerRow) * kLanes) + T(0.5));
  e.dy = rc[kMy] - fy;
  e.dx = rc[kMx] - fx;
  e.bdy = rc[kB] * e.dy;
  const T hcdy2 = rc[kHc] * e.dy * e.dy;
  const simd::Pack<T> power = -(e.dx * (rc[kHa] * e.dx + e.bdy) + hcdy2);
  e.gauss = simd::vexp(power);
  e.araw = rc[kOp] * e.gauss;
  e.alpha = simd::vmin<T>(e.araw, simd::splat(T(kAlphaMax)));
  return e;
}

// A Gaussian's folded channels (ChannelPath kFolded), held for its visits: its extra row x [C] and its group
// entries [e0, e0 + ne) (from its record, when `groups`). The common case of a single entry whose batch slot is NV
// packs wide (the hybrid method's object groups: 4 values forward, 3 gradient channels backward; slot_width is the
// call's) also holds the slot's offset and the entry's first NV values, so its visits need no lookups (the same
// sums as the general path). Both come from the Gaussian's channel record (build_chan_records).
template <class T, int NV>
struct FoldedGaussian {
  T x[kFoldMaxChannels];
  int e0, ne;
  bool one;
  size_t slot;  // id_e0 * NV, when `one`
  T v[NV];      // val_e0[0, NV), when `one`
};
// Fills f in place (no copy of the record per Gaussian) from the record rc and the channel record cr; C = 0 and
// groups = false (cr unread, may be null) give the empty record of the paths that do not fold.
template <class T, int NV>
inline __attribute__((always_inline)) void load_folded(const T* rc, const T* cr, int C, bool groups, int slot_width,
                                                       FoldedGaussian<T, NV>& f) {
  static_assert(NV <= 4 && kCv - kCx == kFoldMaxChannels, "a channel record holds 4 extra and 4 group values");
  // All kFoldMaxChannels values (the record's zero padding past C is never used): a fixed-size copy, where a loop
  // to C became a memcpy call per (tile, Gaussian) pair.
  for (int c = 0; c < kFoldMaxChannels; ++c) f.x[c] = C > 0 ? cr[kCx + c] : T(0);
  f.e0 = groups ? record_int(rc[kE0]) : 0;
  f.ne = groups ? record_int(rc[kNe]) : 0;
  f.one = f.ne == 1 && slot_width == NV;
  f.slot = f.one ? size_t(record_int(cr[kCid])) * NV : 0;
  for (int i = 0; i < NV; ++i) f.v[i] = f.one ? cr[kCv + i] : T(0);
}

// Tiles per chunk of the tile walks' dynamic schedule: runs of consecutive tiles. Neighbours along a tile row share
// most of their Gaussians, whose records, channel records and pair slots a core then finds in its own cache; with
// one tile per chunk, each of T threads walks every T-th tile and reads them all from the shared cache or memory
// (walking the tiles at one thread in the order one thread of 16 walks them made the hybrid backward 9 % slower
// and the forward 6 %, runs of 4 tiles neither; docs/performance.md, session eight). Up to kTileRun, but at least
// kRunChunksPerThread chunks per thread, so that small images keep their schedule's tail short. The order of the
// tiles changes no result (each tile's outputs and pair slots are its own).
constexpr int kTileRun = 4, kRunChunksPerThread = 16;
inline int tile_run(int num_tiles) {
  const int threads = std::max(1, omp_get_max_threads());
  return std::clamp(num_tiles / (threads * kRunChunksPerThread), 1, kTileRun);
}

template <class T>
void ensure_threads(RasterWorkspace<T>& ws) {
  const size_t nt = size_t(std::max(1, omp_get_max_threads()));
  if (ws.threads.size() < nt) ws.threads.resize(nt);
}

}  // namespace hgs::render::HGS_RASTER_NS::detail
