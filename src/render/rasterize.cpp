// Tile rasterizer kernels (forward and backward); the algorithm is described in rasterize.h.
#include "render/rasterize.h"

#include <omp.h>

#include <algorithm>
#include <cstring>

#pragma GCC diagnostic ignored "-Wpsabi"

namespace hgs::render {
namespace {

using simd::kLanes;
constexpr int kBatchesPerRow = kTileSize / kLanes;
constexpr int kBatches = kTileSize * kBatchesPerRow;  // 32 batches of 8 pixels per tile

// Gaussian records: one 16-scalar record per Gaussian (one cache line for float), built once per forward in index
// order and copied per tile into contiguous per-thread scratch (the inner loops read them with broadcasts).
enum Field { kMx, kMy, kHa, kB, kHc, kA, kC, kOp, kCr, kCg, kCb, kZ, kMahal, kEy, kRecord = 16 };
// Backward accumulator slots per Gaussian (and per pair); extras follow.
enum Grad { gMx, gMy, gA, gB, gC, gOp, gR, gG, gBl, gZ, kNumGrads };

template <class T>
struct TileData {
  int n = 0;
  const T* rec = nullptr;      // [n, 16]
};

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
    r[14] = r[15] = 0;
  }
}

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

// Spreads the low 16 bits of x to the even bit positions.
inline uint32_t spread_bits(uint32_t x) {
  x = (x | (x << 8)) & 0x00FF00FFu;
  x = (x | (x << 4)) & 0x0F0F0F0Fu;
  x = (x | (x << 2)) & 0x33333333u;
  x = (x | (x << 1)) & 0x55555555u;
  return x;
}

// Per-batch visit lists of a tile in the thread's scratch (w.vk, w.vw): offsets [33] into one flat array sized
// by the bits `batches` of the masks of Gaussians [0, n) (an upper bound on the visits of every batch).
template <class PerThread>
void size_visit_lists(PerThread& w, const uint32_t* masks, int n, uint32_t batches, int* off) {
  int cnt[kBatches] = {};
  for (int k = 0; k < n; ++k)
    for (uint32_t mb = masks[k] & batches; mb; mb &= mb - 1) ++cnt[__builtin_ctz(mb)];
  off[0] = 0;
  for (int b = 0; b < kBatches; ++b) off[b + 1] = off[b] + cnt[b];
  const size_t nv = size_t(off[kBatches]);
  if (w.vk.size() < nv) w.vk.resize(nv);
  if (w.vw.size() < nv) w.vw.resize(nv);
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

// Extra channels of one batch, forward: dst[c] = sum_v w_v extra_{g_v}[c] over the batch's visits in walk order
// (g_v the Gaussian's index, ex [N, XS] the input rows). The walk itself would read-modify-write every channel
// of the batch state per visit (bound by loads and stores); here a visit costs one weight load and one
// broadcast FMA per channel. The sums run in the same order as a per-visit accumulation: the same values.
template <class T>
void composite_extras(const int* vk, const simd::Pack<T>* vw, int cnt, const T* ex, int C, int XS, simd::Pack<T>* dst) {
  for_channel_chunks(C, [&]<int CH>(int c0) {
    simd::Pack<T> acc[CH];  // local, so the sums stay in registers
    weighted_rows<CH>(vw, cnt, [&](int v) { return ex + size_t(vk[v]) * XS; }, c0, acc);
    for (int i = 0; i < CH; ++i) dst[c0 + i] = acc[i];
  });
}

// Extra channels of one batch, backward: dot[v] = <extra_{g_v}, g> for the batch's visits, g [C] (the batch's
// upstream gradient packs) held in registers a chunk at a time.
template <class T>
void extra_dots(const int* vk, int cnt, const T* ex, int C, int XS, const simd::Pack<T>* g, simd::Pack<T>* dot) {
  using P = simd::Pack<T>;
  for (int v = 0; v < cnt; ++v) dot[v] = P{};
  for_channel_chunks(C, [&]<int CH>(int c0) {
    P gc[CH];
    for (int i = 0; i < CH; ++i) gc[i] = g[c0 + i];
    for (int v = 0; v < cnt; ++v) {
      const T* e = ex + size_t(vk[v]) * XS + c0;
      P d0 = P{}, d1 = P{};
      for (int i = 0; i + 1 < CH; i += 2) {
        d0 += e[i] * gc[i];
        d1 += e[i + 1] * gc[i + 1];
      }
      if (CH % 2) d0 += e[CH - 1] * gc[CH - 1];
      dot[v] += d0 + d1;
    }
  });
}

// Extra-channel gradient of one (tile, Gaussian) pair: o[c] = sum over its visits v of hsum(w_v * g_{b_v}[c]),
// g_b the gradient packs of batch b (stride BS from base).
template <class T>
void extra_grads(const int* vb, const simd::Pack<T>* vw, int cnt, const simd::Pack<T>* base, int BS, int C, T* o) {
  for_channel_chunks(C, [&]<int CH>(int c0) {
    simd::Pack<T> acc[CH];
    weighted_rows<CH>(vw, cnt, [&](int v) { return base + size_t(vb[v]) * BS; }, c0, acc);
    for (int i = 0; i < CH; ++i) o[c0 + i] = simd::hsum<T>(acc[i]);
  });
}

// Batch masks of a tile, masks [n]: bit (row * 2 + half) is set when the Gaussian can reach the 8-pixel batch
// (half a row) with alpha >= 1/255. For each of the 16 pixel rows the exact x-interval where d^T conic d <= m
// (the alpha >= 1/255 region, with margin; binning.h) is computed in double, 4 rows per vector.
template <class T>
void build_masks(const Binning& bins, int tile, const TileData<T>& td, uint32_t* masks) {
  typedef double v4d __attribute__((vector_size(32)));
  typedef int64_t v4l __attribute__((vector_size(32)));
  const int n = td.n;
  const int tx0 = (tile % bins.tiles_x) * kTileSize, ty0 = (tile / bins.tiles_x) * kTileSize;
  v4d rowc[4];  // pixel-centre y of the tile rows
  for (int q = 0; q < 4; ++q)
    for (int l = 0; l < 4; ++l) rowc[q][l] = ty0 + 4 * q + l + 0.5;
  const double bx0[2] = {double(tx0), double(tx0 + kLanes)};
  const double bx1[2] = {double(tx0 + kLanes - 1), double(tx0 + 2 * kLanes - 1)};
  for (int k = 0; k < n; ++k) {
    const T* r = td.rec + size_t(k) * kRecord;
    const double ey = double(r[kEy]);
    const double u = double(r[kMx]), v = double(r[kMy]);
    masks[k] = 0;
    if (ey < 0 || v + ey - 0.5 < ty0 || v - ey - 0.5 > ty0 + kTileSize - 1) continue;
    const double a = double(r[kA]), b = double(r[kB]), c = double(r[kC]);
    const double m = double(r[kMahal]), ndet = b * b - a * c, am = a * m, ia = 1.0 / a;
    uint32_t hit[2] = {0, 0};
    for (int q = 0; q < 4; ++q) {
      const v4d dy = v - rowc[q];
      const v4d disc = dy * dy * ndet + am;
      const v4l valid = disc >= 0.0;
      v4d dc = valid ? disc : v4d{};
#if defined(__AVX__)
      const v4d sq = (v4d)_mm256_sqrt_pd((__m256d)dc);
#else
      v4d sq;
      for (int l = 0; l < 4; ++l) sq[l] = std::sqrt(dc[l]);
#endif
      // pixel x (centre x + 0.5) with dx = u - x - 0.5 in [(-b dy - sq) / a, (-b dy + sq) / a]
      const v4d xl = u - (sq - b * dy) * ia - (0.5 + 1e-3);
      const v4d xr = u + (sq + b * dy) * ia - (0.5 - 1e-3);
      for (int h = 0; h < kBatchesPerRow; ++h) {
        const v4l hm = valid & (xl <= bx1[h]) & (xr >= bx0[h]);
#if defined(__AVX__)
        hit[h] |= uint32_t(_mm256_movemask_pd((__m256d)hm)) << (4 * q);
#else
        for (int l = 0; l < 4; ++l) hit[h] |= uint32_t(hm[l] & 1) << (4 * q + l);
#endif
      }
    }
    masks[k] = spread_bits(hit[0]) | (spread_bits(hit[1]) << 1);
  }
}

// Forward of one tile, Gaussian-major: the tile's Gaussians are walked front to back; each updates the batches
// its mask names that still have a live pixel (per-batch accumulators in per-thread scratch); a batch drops out
// when all its pixels hit the transmittance cut-off, the tile ends when no batch is left.
template <class T, bool kDepth, bool kExtra>
void forward_tile(const RasterInputs<T>& in, const Binning& bins, int tile, typename RasterWorkspace<T>::PerThread& w,
                  const T* records, T* tile_records, uint32_t* ws_masks, T* pair_w,
                  const RasterOutputs<T>& out) {
  using P = simd::Pack<T>;
  using M = simd::Mask<T>;
  using I = typename std::remove_reference<decltype(M{}[0])>::type;
  const int W = bins.width, H = bins.height, C = in.num_extra, J = in.num_weights;
  const int XS = in.extra_stride > 0 ? in.extra_stride : C;
  const int tx0 = (tile % bins.tiles_x) * kTileSize, ty0 = (tile / bins.tiles_x) * kTileSize;
  TileData<T> td;
  const bool any_g = load_records(bins, records, tile_records, true, tile, td);
  const int n = any_g ? td.n : 0;
  uint32_t* masks = ws_masks + bins.tile_start[tile];
  if (any_g) build_masks(bins, tile, td, masks);
  // per-batch state: [T, R, G, B, D, E[C], MW[J]] + active / last masks
  enum { bT, bR, bG, bB, bD, kBatchFixed };
  const int BS = kBatchFixed + C + J;
  if (w.bstate.size() < size_t(kBatches) * BS) w.bstate.resize(size_t(kBatches) * BS);
  if (w.blast.size() < size_t(2) * kBatches) w.blast.resize(size_t(2) * kBatches);
  if (J > 0 && w.wacc.size() < size_t(n) * J) w.wacc.resize(size_t(n) * J);
  P* bst = w.bstate.data();
  M* bact = w.blast.data();
  M* blast = bact + kBatches;
  P* wacc = w.wacc.data();
  const P lane = simd::iota_pack<T>();
  const M lane_i = __builtin_convertvector(lane, M);
  uint32_t alive = 0;
  uint32_t jmask[kBatches];  // pixel-weight maps present in each batch (for_batch_maps)
  for (int bt = 0; bt < kBatches; ++bt) {
    jmask[bt] = 0;
    const int py = ty0 + bt / kBatchesPerRow, px0 = tx0 + (bt % kBatchesPerRow) * kLanes;
    if (py >= H || px0 >= W) continue;
    const int nvalid = std::min(kLanes, W - px0);
    alive |= 1u << bt;
    P* st = bst + size_t(bt) * BS;
    st[bT] = simd::splat(T(1));
    for (int f = bR; f < BS; ++f) st[f] = P{};
    for (int jj = 0; jj < J; ++jj)
      for (int l = 0; l < nvalid; ++l) {
        st[kBatchFixed + C + jj][l] = T(in.pixel_weights[(size_t(py) * W + px0 + l) * J + jj]);
        jmask[bt] |= map_bit(jj, st[kBatchFixed + C + jj][l] != T(0));
      }
    bact[bt] = lane_i < I(nvalid);
    blast[bt] = M{};
  }
  const uint32_t all_batches = alive;
  // Extra channels: the walk records each batch's visits (Gaussian, weight pack); composite_extras sums them
  // afterwards, batch by batch.
  int voff[kBatches + 1], vcnt[kBatches] = {};
  int* vk = nullptr;
  P* vw = nullptr;
  if (kExtra && n > 0) {
    size_visit_lists(w, masks, n, all_batches, voff);
    vk = w.vk.data();
    vw = w.vw.data();
  }
  int kend = 0;  // Gaussians [kend, n) were never reached (all batches terminated)
  for (int k = 0; k < n && alive; ++k) {
    kend = k + 1;
    uint32_t mb = masks[k] & alive;
    if (!mb) {
      if (J > 0)
        for (int jj = 0; jj < J; ++jj) wacc[size_t(k) * J + jj] = P{};
      continue;
    }
    const T* rc = td.rec + size_t(k) * kRecord;
    P* wa = J > 0 ? wacc + size_t(k) * J : nullptr;
    for (int jj = 0; jj < J; ++jj) wa[jj] = P{};
    const M kk = M{} + I(k + 1);
    while (mb) {
      const int bt = __builtin_ctz(mb);
      mb &= mb - 1;
      P* st = bst + size_t(bt) * BS;
      const T fy = T(ty0 + bt / kBatchesPerRow) + T(0.5);
      const P fx = lane + (T(tx0 + (bt % kBatchesPerRow) * kLanes) + T(0.5));
      const T dy = rc[kMy] - fy;
      const P dx = rc[kMx] - fx;
      const T bdy = rc[kB] * dy, hcdy2 = rc[kHc] * dy * dy;
      const P power = -(dx * (rc[kHa] * dx + bdy) + hcdy2);
      const P alpha = simd::vmin<T>(rc[kOp] * simd::vexp(power), simd::splat(T(0.99)));
      M active = bact[bt];
      const M valid = active & (alpha >= T(1.0 / 255.0));
      if (!simd::any(valid)) continue;
      const P Tr = st[bT];
      const P testT = Tr * (T(1) - alpha);
      const M stop = valid & (testT < T(1e-4));
      active = active & ~stop;
      const M acc = valid & ~stop;
      const P wgt = acc ? alpha * Tr : P{};
      st[bR] += wgt * rc[kCr];
      st[bG] += wgt * rc[kCg];
      st[bB] += wgt * rc[kCb];
      if (kDepth) st[bD] += wgt * rc[kZ];
      if (kExtra) {
        const int v = voff[bt] + vcnt[bt]++;
        vk[v] = bins.tile_gauss[bins.tile_start[tile] + k];
        vw[v] = wgt;
      }
      for_batch_maps(jmask[bt], J, [&](int jj) { wa[jj] += wgt * st[kBatchFixed + C + jj]; });
      st[bT] = acc ? testT : Tr;
      blast[bt] = acc ? kk : blast[bt];
      bact[bt] = active;
      if (!simd::any(active)) alive &= ~(1u << bt);
    }
  }
  const T bg0 = in.background[0], bg1 = in.background[1], bg2 = in.background[2];
  for (int bt = 0; bt < kBatches; ++bt) {
    if (!((all_batches >> bt) & 1)) continue;
    const int py = ty0 + bt / kBatchesPerRow, px0 = tx0 + (bt % kBatchesPerRow) * kLanes;
    const int nvalid = std::min(kLanes, W - px0);
    P* st = bst + size_t(bt) * BS;
    if (kExtra && vcnt[bt] > 0) composite_extras<T>(vk + voff[bt], vw + voff[bt], vcnt[bt], in.extra, C, XS, st + kBatchFixed);
    for (int l = 0; l < nvalid; ++l) {
      const size_t p = size_t(py) * W + px0 + l;
      const T Tr = st[bT][l];
      out.rgb[3 * p] = st[bR][l] + Tr * bg0;
      out.rgb[3 * p + 1] = st[bG][l] + Tr * bg1;
      out.rgb[3 * p + 2] = st[bB][l] + Tr * bg2;
      out.alpha[p] = T(1) - Tr;
      out.final_T[p] = Tr;
      out.last[p] = int32_t(blast[bt][l]);
      if (kDepth) out.depth[p] = st[bD][l];
      if (kExtra)
        for (int c = 0; c < C; ++c) out.extra[p * C + c] = st[kBatchFixed + c][l];
    }
  }
  if (J > 0 && any_g) {
    const int s = bins.tile_start[tile];
    for (int k = 0; k < n; ++k) {
      T* o = pair_w + size_t(bins.tile_pair[s + k]) * J;
      if (k < kend && (masks[k] & all_batches))
        for (int jj = 0; jj < J; ++jj) o[jj] = simd::hsum<T>(wacc[size_t(k) * J + jj]);
      else
        for (int jj = 0; jj < J; ++jj) o[jj] = 0;
    }
  }
}

// Backward of one tile, Gaussian-major: the tile's Gaussians are walked back to front (k = n-1 .. 0); each visits
// the batches its mask names, whose per-pixel state (T, S) lives in per-thread scratch, while its gradient
// sums stay in registers and are stored once per (tile, Gaussian) pair.
template <class T, bool kDepth, bool kExtra>
void backward_tile(const RasterInputs<T>& in, const Binning& bins, int tile,
                   typename RasterWorkspace<T>::PerThread& w, const T* final_T, const int32_t* last,
                   const RasterGrads<T>& g, const T* records, T* tile_records, const uint32_t* ws_masks,
                   T* pair_grad) {
  using P = simd::Pack<T>;
  using M = simd::Mask<T>;
  using I = typename std::remove_reference<decltype(M{}[0])>::type;
  const int W = bins.width, H = bins.height, C = in.num_extra, XS = in.extra_stride > 0 ? in.extra_stride : C;
  const int F = kNumGrads + C;
  const int tx0 = (tile % bins.tiles_x) * kTileSize, ty0 = (tile / bins.tiles_x) * kTileSize;
  TileData<T> td;
  if (!load_records(bins, records, tile_records, false, tile, td)) return;
  const int n = td.n;
  const uint32_t* masks = ws_masks + bins.tile_start[tile];
  const int J = g.d_weight_sums ? in.num_weights : 0;
  if (J > 0) {
    if (w.dw.size() < size_t(n) * J) w.dw.resize(size_t(n) * J);
    const int s0 = bins.tile_start[tile];
    for (int k = 0; k < n; ++k)
      for (int jj = 0; jj < J; ++jj)
        w.dw[size_t(k) * J + jj] = g.d_weight_sums[size_t(bins.tile_gauss[s0 + k]) * J + jj];
  }
  const T* DW = w.dw.data();
  // per-batch state: [Tc, S, gr, gg, gb, gd, Tbg, GE[C], MW[J]]
  enum { bT, bS, bR, bG, bB, bD, bBg, kBatchFixed };
  const int BS = kBatchFixed + C + J;
  if (w.bstate.size() < size_t(kBatches) * BS) w.bstate.resize(size_t(kBatches) * BS);
  if (w.blast.size() < size_t(kBatches)) w.blast.resize(kBatches);
  P* bst = w.bstate.data();
  M* blast = w.blast.data();
  int kmax[kBatches];
  uint32_t jmask[kBatches];  // pixel-weight maps present in each batch (for_batch_maps)
  uint32_t live = 0;  // batches with at least one contributor
  const T bg0 = in.background[0], bg1 = in.background[1], bg2 = in.background[2];
  for (int bt = 0; bt < kBatches; ++bt) {
    kmax[bt] = 0;
    jmask[bt] = 0;
    const int py = ty0 + bt / kBatchesPerRow, px0 = tx0 + (bt % kBatchesPerRow) * kLanes;
    if (py >= H || px0 >= W) continue;
    const int nvalid = std::min(kLanes, W - px0);
    P* st = bst + size_t(bt) * BS;
    P Tf = simd::splat(T(1)), gr = P{}, gg = P{}, gb = P{}, ga = P{}, gd = P{};
    M lastp = M{};
    for (int c = 0; c < C + J; ++c) st[kBatchFixed + c] = P{};
    for (int l = 0; l < nvalid; ++l) {
      const size_t p = size_t(py) * W + px0 + l;
      Tf[l] = final_T[p];
      lastp[l] = last[p];
      kmax[bt] = std::max(kmax[bt], int(last[p]));
      if (g.d_rgb) {
        gr[l] = g.d_rgb[3 * p];
        gg[l] = g.d_rgb[3 * p + 1];
        gb[l] = g.d_rgb[3 * p + 2];
      }
      if (g.d_alpha) ga[l] = g.d_alpha[p];
      if (kDepth && g.d_depth) gd[l] = g.d_depth[p];
      if (kExtra && g.d_extra)
        for (int c = 0; c < C; ++c) st[kBatchFixed + c][l] = g.d_extra[p * XS + c];
      for (int jj = 0; jj < J; ++jj) {
        st[kBatchFixed + C + jj][l] = T(in.pixel_weights[p * J + jj]);
        jmask[bt] |= map_bit(jj, st[kBatchFixed + C + jj][l] != T(0));
      }
    }
    if (kmax[bt] == 0) continue;
    live |= 1u << bt;
    st[bT] = Tf;
    st[bS] = P{};
    st[bR] = gr;
    st[bG] = gg;
    st[bB] = gb;
    st[bD] = gd;
    st[bBg] = Tf * (gr * bg0 + gg * bg1 + gb * bg2 - ga);
    blast[bt] = lastp;
  }
  // Extra channels: <extra_k, g> of every (Gaussian, batch) visit is computed before the walk, batch by batch
  // (extra_dots, the batch's gradient packs in registers); the walk keeps each Gaussian's visits (batch, masked
  // weight) and extra_grads sums its channel gradients from them once it is done.
  int voff[kBatches + 1], vcur[kBatches];
  int* vk = nullptr;
  P* vdot = nullptr;
  if (kExtra) {
    int vcnt[kBatches] = {};
    size_visit_lists(w, masks, n, live, voff);
    vk = w.vk.data();
    vdot = w.vw.data();
    for (int k = 0; k < n; ++k)
      for (uint32_t mb = masks[k] & live; mb; mb &= mb - 1) {
        const int bt = __builtin_ctz(mb);
        if (k < kmax[bt]) vk[voff[bt] + vcnt[bt]++] = bins.tile_gauss[bins.tile_start[tile] + k];
      }
    for (int bt = 0; bt < kBatches; ++bt) {
      vcur[bt] = vcnt[bt];
      if (vcnt[bt] > 0)
        extra_dots<T>(vk + voff[bt], vcnt[bt], in.extra, C, XS, bst + size_t(bt) * BS + kBatchFixed, vdot + voff[bt]);
    }
  }
  int kvb[kBatches];  // this Gaussian's visits with a contribution: batch, masked weight
  P kvw[kBatches];
  const P lane = simd::iota_pack<T>();
  const int s = bins.tile_start[tile];
  for (int k = n - 1; k >= 0; --k) {
    uint32_t mb = masks[k] & live;
    T* o = pair_grad + size_t(bins.tile_pair[s + k]) * F;
    P aMx = P{}, aMy = P{}, aA = P{}, aB = P{}, aC = P{}, aOp = P{}, aR = P{}, aG = P{}, aBl = P{}, aZ = P{};
    int nkv = 0;
    const T* rc = td.rec + size_t(k) * kRecord;
    const T* dw = J > 0 ? DW + size_t(k) * J : nullptr;
    while (mb) {
      const int bt = __builtin_ctz(mb);
      mb &= mb - 1;
      if (k >= kmax[bt]) continue;
      const int vi = kExtra ? voff[bt] + --vcur[bt] : 0;  // this visit in the batch's list (walked backwards)
      P* st = bst + size_t(bt) * BS;
      const M inr = (M{} + I(k)) < blast[bt];
      const T fy = T(ty0 + bt / kBatchesPerRow) + T(0.5);
      const P fx = lane + (T(tx0 + (bt % kBatchesPerRow) * kLanes) + T(0.5));
      const T dy = rc[kMy] - fy;
      const P dx = rc[kMx] - fx;
      const T bdy = rc[kB] * dy, hcdy2 = rc[kHc] * dy * dy;
      const P power = -(dx * (rc[kHa] * dx + bdy) + hcdy2);
      const P gauss = simd::vexp(power);
      const P araw = rc[kOp] * gauss;
      const P alpha = simd::vmin<T>(araw, simd::splat(T(0.99)));
      const M c = inr & (alpha >= T(1.0 / 255.0));
      if (!simd::any(c)) continue;
      const P gr = st[bR], gg = st[bG], gb = st[bB];
      const P ioma = simd::vrecip(T(1) - alpha);
      const P Ti = st[bT] * ioma;
      const P wgt = alpha * Ti;
      P dot = rc[kCr] * gr + rc[kCg] * gg + rc[kCb] * gb;
      if (kDepth) dot += rc[kZ] * st[bD];
      if (kExtra) dot += vdot[vi];
      if (J > 0) {
        // Pixel-weight sums: only the maps that are non-zero in this batch (one, inside a hard object mask).
        const P* sw = st + kBatchFixed + C;
        P d0 = P{};
        for_batch_maps(jmask[bt], J, [&](int jj) { d0 += dw[jj] * sw[jj]; });
        dot += d0;
      }
      const P S = st[bS];
      P dLda = Ti * dot - (S + st[bBg]) * ioma;
      st[bS] = c ? S + wgt * dot : S;
      st[bT] = c ? Ti : st[bT];
      const P wm = c ? wgt : P{};
      aR += wm * gr;
      aG += wm * gg;
      aBl += wm * gb;
      if (kDepth) aZ += wm * st[bD];
      if (kExtra) {
        kvb[nkv] = bt;
        kvw[nkv++] = wm;
      }
      dLda = (c & (araw < T(0.99))) ? dLda : P{};
      aOp += gauss * dLda;
      const P pw = araw * dLda;  // dL/dpower
      const P pdx = pw * dx;
      aMx += rc[kA] * pdx + bdy * pw;
      aMy += rc[kB] * pdx + (rc[kC] * dy) * pw;
      aA += pdx * dx;
      aB += pdx * dy;
      aC += pw * (dy * dy);
    }
    // per-pair results (dpower/dmx = -(a dx + b dy), dpower/da = -dx^2 / 2, dpower/db = -dx dy, ...)
    o[gMx] = -simd::hsum<T>(aMx);
    o[gMy] = -simd::hsum<T>(aMy);
    o[gA] = T(-0.5) * simd::hsum<T>(aA);
    o[gB] = -simd::hsum<T>(aB);
    o[gC] = T(-0.5) * simd::hsum<T>(aC);
    o[gOp] = simd::hsum<T>(aOp);
    o[gR] = simd::hsum<T>(aR);
    o[gG] = simd::hsum<T>(aG);
    o[gBl] = simd::hsum<T>(aBl);
    o[gZ] = kDepth ? simd::hsum<T>(aZ) : T(0);
    if (kExtra) extra_grads<T>(kvb, kvw, nkv, bst + kBatchFixed, BS, C, o + kNumGrads);
    else
      for (int ch = 0; ch < C; ++ch) o[kNumGrads + ch] = T(0);
  }
}

template <class T>
void ensure_threads(RasterWorkspace<T>& ws) {
  const size_t nt = size_t(std::max(1, omp_get_max_threads()));
  if (ws.threads.size() < nt) ws.threads.resize(nt);
}

}  // namespace

template <class T>
void rasterize_forward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws,
                       const RasterOutputs<T>& out) {
  ensure_threads(ws);
  const bool dep = in.depth != nullptr, ext = in.num_extra > 0;
  if (ws.masks.size() < size_t(bins.num_pairs)) ws.masks.resize(size_t(bins.num_pairs));
  uint32_t* MK = ws.masks.data();
  if (ws.records.size() < size_t(in.n) * kRecord) ws.records.resize(size_t(in.n) * kRecord);
  build_records(in, bins, ws.records.data());
  const T* R = ws.records.data();
  if (ws.tile_records.size() < size_t(bins.num_pairs) * kRecord) ws.tile_records.resize(size_t(bins.num_pairs) * kRecord);
  T* TR = ws.tile_records.data();
  const int J = in.num_weights;
  if (J > 0 && ws.pair_w.size() < size_t(bins.num_pairs) * J) ws.pair_w.resize(size_t(bins.num_pairs) * J);
  T* PW = ws.pair_w.data();
#pragma omp parallel
  {
    auto& w = ws.threads[omp_get_thread_num()];
#pragma omp for schedule(dynamic, 1)
    for (int t = 0; t < bins.num_tiles; ++t) {
      if (dep && ext) forward_tile<T, true, true>(in, bins, t, w, R, TR, MK, PW, out);
      else if (dep) forward_tile<T, true, false>(in, bins, t, w, R, TR, MK, PW, out);
      else if (ext) forward_tile<T, false, true>(in, bins, t, w, R, TR, MK, PW, out);
      else forward_tile<T, false, false>(in, bins, t, w, R, TR, MK, PW, out);
    }
    if (J > 0) {
#pragma omp for schedule(static)
      for (int i = 0; i < in.n; ++i) {
        T* o = out.weight_sums + size_t(i) * J;
        for (int jj = 0; jj < J; ++jj) o[jj] = 0;
        for (int p = bins.pair_offset[i]; p < bins.pair_offset[i + 1]; ++p)
          for (int jj = 0; jj < J; ++jj) o[jj] += PW[size_t(p) * J + jj];
      }
    }
  }
}

template <class T>
void rasterize_backward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws, const T* final_T,
                        const int32_t* last, const RasterGrads<T>& g) {
  ensure_threads(ws);
  const int C = in.num_extra, F = kNumGrads + C, XS = in.extra_stride > 0 ? in.extra_stride : C;
  const bool dep = in.depth != nullptr && g.d_depth != nullptr;
  const bool ext = C > 0 && g.d_extra != nullptr;
  if (ws.pair_grad.size() < size_t(bins.num_pairs) * F) ws.pair_grad.resize(size_t(bins.num_pairs) * F);
  T* pg = ws.pair_grad.data();
  const uint32_t* MK = ws.masks.data();
  const T* R = ws.records.data();
  T* TR = ws.tile_records.data();
#pragma omp parallel
  {
    auto& w = ws.threads[omp_get_thread_num()];
#pragma omp for schedule(dynamic, 1)
    for (int t = 0; t < bins.num_tiles; ++t) {
      if (dep && ext) backward_tile<T, true, true>(in, bins, t, w, final_T, last, g, R, TR, MK, pg);
      else if (dep) backward_tile<T, true, false>(in, bins, t, w, final_T, last, g, R, TR, MK, pg);
      else if (ext) backward_tile<T, false, true>(in, bins, t, w, final_T, last, g, R, TR, MK, pg);
      else backward_tile<T, false, false>(in, bins, t, w, final_T, last, g, R, TR, MK, pg);
    }
    // reduce pair slots per Gaussian in a fixed order
#pragma omp for schedule(static)
    for (int i = 0; i < in.n; ++i) {
      T s[kNumGrads] = {};
      T* gex = g.extra ? g.extra + size_t(i) * XS : nullptr;
      if (gex)
        for (int ch = 0; ch < XS; ++ch) gex[ch] = 0;  // channels [C, XS) carry no gradient
      for (int p = bins.pair_offset[i]; p < bins.pair_offset[i + 1]; ++p) {
        const T* o = pg + size_t(p) * F;
        for (int f = 0; f < kNumGrads; ++f) s[f] += o[f];
        if (gex)
          for (int ch = 0; ch < C; ++ch) gex[ch] += o[kNumGrads + ch];
      }
      g.mean2d[2 * i] = s[gMx];
      g.mean2d[2 * i + 1] = s[gMy];
      g.conic[3 * i] = s[gA];
      g.conic[3 * i + 1] = s[gB];
      g.conic[3 * i + 2] = s[gC];
      g.opacity[i] = s[gOp];
      g.color[3 * i] = s[gR];
      g.color[3 * i + 1] = s[gG];
      g.color[3 * i + 2] = s[gBl];
      if (g.depth) g.depth[i] = s[gZ];
    }
  }
}

template void rasterize_forward<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                       const RasterOutputs<float>&);
template void rasterize_forward<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                        const RasterOutputs<double>&);
template void rasterize_backward<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                        const float*, const int32_t*, const RasterGrads<float>&);
template void rasterize_backward<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                         const double*, const int32_t*, const RasterGrads<double>&);

}  // namespace hgs::render
