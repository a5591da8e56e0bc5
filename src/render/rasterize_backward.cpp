// Tile rasterizer, backward: the exact gradient of rasterize_forward (rasterize.h has the whole algorithm). Each
// tile walks its Gaussians back to front (Gaussian-major) over the batches of their forward masks, starting at
// each pixel's last contributor: T_i = T_{i+1} / (1 - alpha_i) is rebuilt from the saved final T and one scalar
// per pixel S = sum_{j>i} w_j <value_j, dL/dout> gives dL/dalpha_i = T_i <value_i, g> - (S + T_final (<bg, g_rgb>
// - g_alpha)) / (1 - alpha_i); no gradient flows through the kAlphaMax clamp, and pixels below kAlphaMin are
// skipped as in forward. Extra channels and groups: folded into the walk (each visit's dot and the Gaussian's
// gradient sums on the stack), or, with many channels, dots precomputed per visit (extra_dots, group_dots) and
// the channel gradients summed per Gaussian afterwards (extra_grads, group_grads); the same sums in the same
// order, with the walk's fused multiply-adds pinned (simd::fmadd) so that both paths round alike. Per-(tile,
// Gaussian) slots are reduced per Gaussian in a fixed
// order, so the result is bitwise deterministic for any thread count.
#include "render/raster_isa.h"

#include <omp.h>

#include <algorithm>
#include <cstring>
#include <tuple>

#include "render/rasterize_common.h"

#pragma GCC diagnostic ignored "-Wpsabi"

#include "render/raster_isa_begin.h"

namespace hgs::render::HGS_RASTER_NS {
using namespace detail;
namespace {

// Backward accumulator slots per Gaussian (and per pair); extras follow.
enum Grad { gMx, gMy, gA, gB, gC, gOp, gR, gG, gBl, gZ, kNumGrads };

// One chunk of CH channels of <e, g> (e a Gaussian's values, g the batch's upstream gradient packs): even and
// odd channels in two sums.
template <int CH, class T>
inline __attribute__((always_inline)) simd::Pack<T> chunk_dot(const T* e, const simd::Pack<T>* gc) {
  simd::Pack<T> d0 = simd::Pack<T>{}, d1 = simd::Pack<T>{};
  for (int i = 0; i + 1 < CH; i += 2) {
    d0 += e[i] * gc[i];
    d1 += e[i + 1] * gc[i + 1];
  }
  if (CH % 2) d0 += e[CH - 1] * gc[CH - 1];
  return d0 + d1;
}

// <e, g> of one visit over C channels: the chunks summed in order.
template <class T>
inline __attribute__((always_inline)) simd::Pack<T> extra_dot(const T* e, int C, const simd::Pack<T>* g) {
  simd::Pack<T> dot = simd::Pack<T>{};
  for_channel_chunks(C, [&]<int CH>(int c0) { dot += chunk_dot<CH>(e + c0, g + c0); });
  return dot;
}

// Extra channels of one batch, backward (the visit-list path): dot[v] = <extra_{g_v}, g> for the batch's visits,
// g [C] the batch's upstream gradient packs. A few channels: extra_dot per visit (the folded walk's own function,
// so both paths agree bitwise); more: chunk by chunk over the visits, the chunk's gradient packs in registers,
// the same sums in the same order.
template <class T>
void extra_dots(const int* vk, int cnt, const T* ex, int C, int XS, const simd::Pack<T>* g, simd::Pack<T>* dot) {
  using P = simd::Pack<T>;
  if (C <= kFoldMaxChannels) {
    for (int v = 0; v < cnt; ++v) dot[v] = extra_dot(ex + size_t(vk[v]) * XS, C, g);
    return;
  }
  for (int v = 0; v < cnt; ++v) dot[v] = P{};
  for_channel_chunks(C, [&]<int CH>(int c0) {
    P gc[CH];
    for (int i = 0; i < CH; ++i) gc[i] = g[c0 + i];
    for (int v = 0; v < cnt; ++v) dot[v] += chunk_dot<CH>(ex + size_t(vk[v]) * XS + c0, gc);
  });
}

// Extra-channel gradient of one (tile, Gaussian) pair: o[c] = sum over its visits v of hsum(w_v * g_{b_v}[c]),
// g_b the gradient packs of batch b (stride BS from base).
template <class T>
void extra_grads(const int* vb, const simd::Pack<T>* vw, int cnt, const simd::Pack<T>* base, int BS, int C, T* o) {
  for_channel_chunks(C, [&]<int CH>(int c0) {
    simd::Pack<T> acc[CH];
    weighted_rows<CH>(
        vw, cnt, [&](int v) { return base + size_t(vb[v]) * BS; }, c0, acc);
    for (int i = 0; i < CH; ++i) o[c0 + i] = simd::hsum<T>(acc[i]);
  });
}

// One Gaussian's sum_e <val_e[0, GWg), g[id_e]> over its entries [e0, e1), g [G * GWg] a batch's group gradient
// packs (the visit-list path's group_dots and the folded walk both call this).
template <class T>
inline __attribute__((always_inline)) simd::Pack<T> group_dot(const RasterInputs<T>& in, int e0, int e1, int GWg,
                                                              const simd::Pack<T>* g) {
  simd::Pack<T> d = simd::Pack<T>{};
  for (int e = e0; e < e1; ++e) {
    const simd::Pack<T>* gs = g + size_t(in.group_id[e]) * GWg;
    const T* x = in.group_val + size_t(e) * in.group_width;
    for (int i = 0; i < GWg; ++i) d += x[i] * gs[i];
  }
  return d;
}

// Sparse groups of one batch, backward: dot[v] += sum_e <val_e[0, GWg), g[id_e]> over the entries of the visit's
// Gaussian, g [G * GWg] the batch's group gradient packs.
template <class T>
void group_dots(const int* vk, int cnt, const RasterInputs<T>& in, const simd::Pack<T>* g, simd::Pack<T>* dot) {
  const int GWg = in.group_grad_width;
  for (int v = 0; v < cnt; ++v) dot[v] += group_dot(in, in.group_ptr[vk[v]], in.group_ptr[vk[v] + 1], GWg, g);
}

// Group gradients of one (tile, Gaussian) pair: o[e', i] = sum over its visits v of hsum(w_v * g_{b_v}[id_e, i])
// for the Gaussian's entries e = ptr[gi] + e', i < GWg; g_b the group gradient packs of batch b (stride BS from
// base).
template <class T>
void group_grads(const int* vb, const simd::Pack<T>* vw, int cnt, const simd::Pack<T>* base, int BS,
                 const RasterInputs<T>& in, int gi, T* o) {
  using P = simd::Pack<T>;
  const int GWg = in.group_grad_width;
  for (int e = in.group_ptr[gi]; e < in.group_ptr[gi + 1]; ++e, o += GWg) {
    const size_t off = size_t(in.group_id[e]) * GWg;
    for (int i = 0; i < GWg; ++i) {
      P acc = P{};
      for (int v = 0; v < cnt; ++v) acc += vw[v] * base[size_t(vb[v]) * BS + off + i];
      o[i] = simd::hsum<T>(acc);
    }
  }
}

// Backward of one tile, Gaussian-major: the tile's Gaussians are walked back to front (k = n-1 .. 0); each visits
// the batches its mask names, whose per-pixel state (T, S) lives in per-thread scratch, while its gradient
// sums stay in registers and are stored once per (tile, Gaussian) pair.
template <class T, bool kDepth, int kX>
void backward_tile(const RasterInputs<T>& in, const Binning& bins, int tile, typename RasterWorkspace<T>::PerThread& w,
                   const T* final_T, const int32_t* last, const RasterGrads<T>& g, const T* records, T* tile_records,
                   const uint32_t* ws_masks, T* pair_grad, const size_t* pair_gslot, T* pair_group) {
  using P = simd::Pack<T>;
  using M = simd::Mask<T>;
  using I = typename std::remove_reference<decltype(M{}[0])>::type;
  constexpr bool kExtra = kX != kNoChannels, kLists = kX == kVisitLists, kFold = kX == kFolded;
  const int W = bins.width, H = bins.height, C = in.num_extra, XS = in.extra_stride > 0 ? in.extra_stride : C;
  const int F = kNumGrads + C;
  const int GWg = g.group_grads() ? in.group_grad_width : 0, GT = in.num_groups * GWg;  // group gradient channels
  const int tx0 = (tile % bins.tiles_x) * kTileSize, ty0 = (tile / bins.tiles_x) * kTileSize;
  TileData<T> td;
  if (!load_records(bins, records, tile_records, false, tile, td)) return;
  const int n = td.n;
  const uint32_t* masks = ws_masks + bins.tile_start[tile];
  const int J = g.d_weight_sums ? in.num_weights : 0;
  T* DW = J > 0 ? w.dw.template get<T>(size_t(n) * J) : nullptr;
  if (J > 0) {
    const int s0 = bins.tile_start[tile];
    for (int k = 0; k < n; ++k)
      for (int jj = 0; jj < J; ++jj) DW[size_t(k) * J + jj] = g.d_weight_sums[size_t(bins.tile_gauss[s0 + k]) * J + jj];
  }
  // per-batch state: [Tc, S, gr, gg, gb, gd, Tbg, GE[C], MW[J], GG[G * GWg]]
  enum { bT, bS, bR, bG, bB, bD, bBg, kBatchFixed };
  const int BS = kBatchFixed + C + J + GT, GO = kBatchFixed + C + J;
  P* bst = w.bstate.template get<P>(size_t(kBatches) * BS);
  M* blast = w.blast.template get<M>(kBatches);
  // The groups the tile's Gaussians have entries in: only their upstream gradients are loaded (no Gaussian of
  // the tile reads another group's).
  int ng = 0;
  int* glist = nullptr;
  if (kExtra && GT > 0) {
    glist = w.groups.template get<int>(size_t(2) * in.num_groups);  // the list, then the flags
    ng = tile_groups(in, td, reinterpret_cast<uint8_t*>(glist + in.num_groups), glist);
  }
  int kmax[kBatches];
  uint32_t jmask[kBatches];  // pixel-weight maps present in each batch (for_batch_maps)
  uint32_t live = 0;         // batches with at least one contributor
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
    for (int u = 0; u < ng; ++u)
      for (int i = 0; i < GWg; ++i) st[GO + glist[u] * GWg + i] = P{};
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
      if (kExtra && GT > 0 && g.d_groups) {
        const T* dg = g.d_groups + p * size_t(g.d_group_row);
        for (int u = 0; u < ng; ++u) {
          const int gi = glist[u];
          for (int i = 0; i < GWg; ++i) st[GO + gi * GWg + i][l] = dg[size_t(gi) * g.d_group_stride + i];
        }
      }
      for (int jj = 0; jj < J; ++jj) {
        st[kBatchFixed + C + jj][l] = T(in.pixel_weights[p * J + jj]);
        jmask[bt] |= map_bit(jj, st[kBatchFixed + C + jj][l] != T(0));
      }
    }
    if (kmax[bt] == 0) continue;
    if (kExtra && GT > 0 && g.d_group_rows) {  // the batch's row of each of the tile's groups, on demand
      T row[kLanes * kMaxGroupGradWidth];
      for (int u = 0; u < ng; ++u) {
        const int gi = glist[u];
        g.d_group_rows(g.d_group_ctx, gi, py, px0, nvalid, row);
        for (int l = 0; l < nvalid; ++l)
          for (int i = 0; i < GWg; ++i) st[GO + gi * GWg + i][l] = row[l * GWg + i];
      }
    }
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
  if (kLists) {
    int vcnt[kBatches] = {};
    std::tie(vk, vdot) = size_visit_lists<P>(w, masks, n, live, voff);
    for (int k = 0; k < n; ++k)
      for (uint32_t mb = masks[k] & live; mb; mb &= mb - 1) {
        const int bt = __builtin_ctz(mb);
        if (k < kmax[bt]) vk[voff[bt] + vcnt[bt]++] = bins.tile_gauss[bins.tile_start[tile] + k];
      }
    for (int bt = 0; bt < kBatches; ++bt) {
      vcur[bt] = vcnt[bt];
      if (vcnt[bt] == 0) continue;
      extra_dots<T>(vk + voff[bt], vcnt[bt], in.extra, C, XS, bst + size_t(bt) * BS + kBatchFixed, vdot + voff[bt]);
      if (GT > 0) group_dots<T>(vk + voff[bt], vcnt[bt], in, bst + size_t(bt) * BS + GO, vdot + voff[bt]);
    }
  }
  T* fx = nullptr;  // folded extra channels in tile order [n, 4]
  if (kFold && C > 0) {
    fx = w.fold.template get<T>(size_t(n) * kFoldMaxChannels);
    gather_tile_channels(bins, tile, in.extra, C, XS, fx);
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
    // Folded channels: the Gaussian's extra row (tile order) and group entries (from its record); their gradient
    // sums (ae, ag) on the stack.
    // (Copied to a local array: the visits' stores to the batch state cannot alias it, so it stays in registers.)
    T xr[kFoldMaxChannels];
    if (kFold)
      for (int c = 0; c < C; ++c) xr[c] = fx[size_t(k) * kFoldMaxChannels + c];
    const int e0 = kFold && GT > 0 ? record_int(rc[kE0]) : 0, ne = kFold && GT > 0 ? record_int(rc[kNe]) : 0;
    P ae[kFoldMaxChannels], ag[kFoldMaxEntries * kFoldMaxWidth];
    // The common case of one group entry with 3 gradient channels (the hybrid method's object groups): its slot
    // and values held for the Gaussian's visits instead of looked up on each (the same sums).
    const bool one3 = kFold && GT > 0 && ne == 1 && GWg == 3;
    const size_t g1 = one3 ? size_t(in.group_id[e0]) * 3 : 0;
    const T* gv = one3 ? in.group_val + size_t(e0) * in.group_width : nullptr;
    const T v0 = one3 ? gv[0] : T(0), v1 = one3 ? gv[1] : T(0), v2 = one3 ? gv[2] : T(0);
    if constexpr (kFold) {
      for (int c = 0; c < C; ++c) ae[c] = P{};
      for (int i = 0; i < ne * GWg; ++i) ag[i] = P{};
    }
    while (mb) {
      const int bt = __builtin_ctz(mb);
      mb &= mb - 1;
      if (k >= kmax[bt]) continue;
      const int vi = kLists ? voff[bt] + --vcur[bt] : 0;  // this visit in the batch's list (walked backwards)
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
      const P alpha = simd::vmin<T>(araw, simd::splat(T(kAlphaMax)));
      const M c = inr & (alpha >= T(kAlphaMin));
      if (!simd::any(c)) continue;
      const P gr = st[bR], gg = st[bG], gb = st[bB];
      const P ioma = simd::vrecip(T(1) - alpha);
      const P Ti = st[bT] * ioma;
      const P wgt = alpha * Ti;
      P dot = rc[kCr] * gr + rc[kCg] * gg + rc[kCb] * gb;
      if (kDepth) dot += rc[kZ] * st[bD];
      if constexpr (kLists) dot += vdot[vi];
      if constexpr (kFold) {  // extra_dots + group_dots of this visit, in their order
        P vd = C > 0 ? extra_dot(xr, C, st + kBatchFixed) : P{};
        if (one3) {  // group_dot's sum
          const P* gs = st + GO + g1;
          P d = P{};
          d += v0 * gs[0];
          d += v1 * gs[1];
          d += v2 * gs[2];
          vd += d;
        } else if (GT > 0) {
          vd += group_dot(in, e0, e0 + ne, GWg, st + GO);
        }
        dot += vd;
      }
      if (J > 0) {
        // Pixel-weight sums: only the maps that are non-zero in this batch (one, inside a hard object mask).
        const P* sw = st + kBatchFixed + C;
        P d0 = P{};
        for_batch_maps(jmask[bt], J, [&](int jj) { d0 += dw[jj] * sw[jj]; });
        dot += d0;
      }
      const P S = st[bS];
      P dLda = simd::fmadd(Ti, dot, -((S + st[bBg]) * ioma));  // one rounding in both channel paths
      st[bS] = c ? S + wgt * dot : S;
      st[bT] = c ? Ti : st[bT];
      const P wm = c ? wgt : P{};
      aR += wm * gr;
      aG += wm * gg;
      aBl += wm * gb;
      if (kDepth) aZ += wm * st[bD];
      if constexpr (kLists) {
        kvb[nkv] = bt;
        kvw[nkv++] = wm;
      }
      dLda = (c & (araw < T(kAlphaMax))) ? dLda : P{};
      aOp += gauss * dLda;
      const P pw = araw * dLda;  // dL/dpower
      const P pdx = pw * dx;
      aMx += simd::fmadd(simd::splat(rc[kA]), pdx, bdy * pw);  // as GCC contracts them, pinned (fmadd)
      aMy += simd::fmadd(simd::splat(rc[kB]), pdx, (rc[kC] * dy) * pw);
      aA += pdx * dx;
      aB += pdx * dy;
      aC += pw * (dy * dy);
      if constexpr (kFold) {  // extra_grads / group_grads of this visit
        for (int c = 0; c < C; ++c) ae[c] += wm * st[kBatchFixed + c];
        if (one3) {
          const P* gs = st + GO + g1;
          ag[0] += wm * gs[0];
          ag[1] += wm * gs[1];
          ag[2] += wm * gs[2];
        } else {
          for (int e = 0; e < ne; ++e) {
            const P* gs = st + GO + size_t(in.group_id[e0 + e]) * GWg;
            for (int i = 0; i < GWg; ++i) ag[e * GWg + i] += wm * gs[i];
          }
        }
      }
    }
    // per-pair results (dpower/dmx = -(a dx + b dy), dpower/da = -dx^2 / 2, dpower/db = -dx dy, ...); the first
    // 8 slots' lane sums at once (simd::hsum8, bitwise the 8 hsums), scaled as named
    {
      static_assert(gMx == 0 && gMy == 1 && gA == 2 && gB == 3 && gC == 4 && gOp == 5 && gR == 6 && gG == 7);
      const P acc[8] = {aMx, aMy, aA, aB, aC, aOp, aR, aG};
      const P sums = simd::hsum8(acc) * P{T(-1), T(-1), T(-0.5), T(-1), T(-0.5), T(1), T(1), T(1)};
      std::memcpy(o, &sums, sizeof(sums));
    }
    o[gBl] = simd::hsum<T>(aBl);
    o[gZ] = kDepth ? simd::hsum<T>(aZ) : T(0);
    if constexpr (kLists) {
      extra_grads<T>(kvb, kvw, nkv, bst + kBatchFixed, BS, C, o + kNumGrads);
    } else if constexpr (kFold) {
      for (int c = 0; c < C; ++c) o[kNumGrads + c] = simd::hsum<T>(ae[c]);
    } else {
      for (int ch = 0; ch < C; ++ch) o[kNumGrads + ch] = T(0);
    }
    if (kExtra && GT > 0) {
      T* og = pair_group + pair_gslot[s + k];
      if constexpr (kLists) {
        group_grads<T>(kvb, kvw, nkv, bst + GO, BS, in, bins.tile_gauss[s + k], og);
      } else if constexpr (kFold) {
        for (int i = 0; i < ne * GWg; ++i) og[i] = simd::hsum<T>(ag[i]);
      }
    }
  }
}

}  // namespace

template <class T>
void rasterize_backward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws, const T* final_T,
                        const int32_t* last, const RasterGrads<T>& g) {
  ensure_threads(ws);
  const int C = in.num_extra, F = kNumGrads + C, XS = in.extra_stride > 0 ? in.extra_stride : C;
  const bool dep = in.depth != nullptr && g.d_depth != nullptr;
  const int GWg = g.group_grads() ? in.group_grad_width : 0, GW = in.group_width;
  const bool groups = in.num_groups > 0 && GWg > 0;
  const bool ext = (C > 0 && g.d_extra != nullptr) || groups;
  if (ws.pair_grad.size() < size_t(bins.num_pairs) * F) ws.pair_grad.resize(size_t(bins.num_pairs) * F);
  if (groups) {  // each Gaussian's group gradients: one slot of entries x GWg per pair, Gaussian-major
    ws.group_off.resize(size_t(in.n) + 1);
    ws.group_off[0] = 0;
    for (int i = 0; i < in.n; ++i)
      ws.group_off[i + 1] = ws.group_off[i] + size_t(bins.pair_offset[i + 1] - bins.pair_offset[i]) *
                                                  size_t(in.group_ptr[i + 1] - in.group_ptr[i]) * GWg;
    if (ws.pair_group.size() < ws.group_off[in.n]) ws.pair_group.resize(ws.group_off[in.n]);
  }
  int max_entries = 0;  // the most group entries of one Gaussian (the folded backward's bound)
  if (groups) {
#pragma omp parallel for schedule(static) reduction(max : max_entries)
    for (int i = 0; i < in.n; ++i) max_entries = std::max(max_entries, in.group_ptr[i + 1] - in.group_ptr[i]);
  }
  const int x = ext ? channel_path(in, C, groups ? in.num_groups * GWg : 0, max_entries, GWg) : kNoChannels;
  const size_t* GOF = groups ? ws.group_off.data() : nullptr;
  if (groups) {  // each pair's slot in tile order (the walks then write them without looking up its Gaussian)
    if (ws.pair_gslot.size() < size_t(bins.num_pairs)) ws.pair_gslot.resize(size_t(bins.num_pairs));
    size_t* slot = ws.pair_gslot.data();
#pragma omp parallel for schedule(static)
    for (int t = 0; t < bins.num_pairs; ++t) {
      const int gi = bins.tile_gauss[t];
      slot[t] = GOF[gi] + size_t(bins.tile_pair[t] - bins.pair_offset[gi]) *
                              size_t(in.group_ptr[gi + 1] - in.group_ptr[gi]) * GWg;
    }
  }
  const size_t* GSL = groups ? ws.pair_gslot.data() : nullptr;
  T* PGR = groups ? ws.pair_group.data() : nullptr;
  T* pg = ws.pair_grad.data();
  const uint32_t* MK = ws.masks.data();
  const T* R = ws.records.data();
  T* TR = ws.tile_records.data();
#pragma omp parallel
  {
    auto& w = ws.threads[omp_get_thread_num()];
#pragma omp for schedule(dynamic, 1)
    for (int t = 0; t < bins.num_tiles; ++t) {
      if (dep && x == kVisitLists)
        backward_tile<T, true, kVisitLists>(in, bins, t, w, final_T, last, g, R, TR, MK, pg, GSL, PGR);
      else if (dep && x == kFolded)
        backward_tile<T, true, kFolded>(in, bins, t, w, final_T, last, g, R, TR, MK, pg, GSL, PGR);
      else if (dep) backward_tile<T, true, kNoChannels>(in, bins, t, w, final_T, last, g, R, TR, MK, pg, GSL, PGR);
      else if (x == kVisitLists)
        backward_tile<T, false, kVisitLists>(in, bins, t, w, final_T, last, g, R, TR, MK, pg, GSL, PGR);
      else if (x == kFolded)
        backward_tile<T, false, kFolded>(in, bins, t, w, final_T, last, g, R, TR, MK, pg, GSL, PGR);
      else backward_tile<T, false, kNoChannels>(in, bins, t, w, final_T, last, g, R, TR, MK, pg, GSL, PGR);
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
      if (g.group_val && in.num_groups > 0) {  // entries x GW; pair slots are entries x GWg
        const int e0 = in.group_ptr[i], ne = in.group_ptr[i + 1] - e0;
        T* gv = g.group_val + size_t(e0) * GW;
        for (int c = 0; c < ne * GW; ++c) gv[c] = 0;
        if (groups)
          for (int p = bins.pair_offset[i]; p < bins.pair_offset[i + 1]; ++p) {
            const T* o = PGR + GOF[i] + size_t(p - bins.pair_offset[i]) * ne * GWg;
            for (int e = 0; e < ne; ++e)
              for (int c = 0; c < GWg; ++c) gv[size_t(e) * GW + c] += o[e * GWg + c];
          }
      }
    }
  }
}

template void rasterize_backward<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                        const float*, const int32_t*, const RasterGrads<float>&);
template void rasterize_backward<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                         const double*, const int32_t*, const RasterGrads<double>&);

}  // namespace hgs::render::HGS_RASTER_NS

#include "render/raster_isa_end.h"
