// Tile rasterizer, backward: the exact gradient of rasterize_forward (rasterize.h has the whole algorithm). Each
// tile walks its Gaussians back to front (Gaussian-major) over the batches of their forward masks, starting at
// each pixel's last contributor: T_i = T_{i+1} / (1 - alpha_i) is rebuilt from the saved final T and one scalar
// per pixel S = sum_{j>i} w_j <value_j, dL/dout> gives dL/dalpha_i = T_i <value_i, g> - (S + T_final (<bg, g_rgb>
// - g_alpha)) / (1 - alpha_i); no gradient flows through the kAlphaMax clamp, and pixels below kAlphaMin are
// skipped as in forward. Extra channels and groups: folded into the walk (each visit's dot and the Gaussian's
// gradient sums on the stack; a Gaussian with more group entries than kFoldMaxEntries records its visits and sums
// its group gradients afterwards, group_grads), or, with many channels, dots precomputed per visit (extra_dots,
// group_dots) and the channel gradients summed per Gaussian afterwards (extra_grads, group_grads); the same sums
// in the same order, with the walk's fused multiply-adds pinned (simd::fmadd) so that both paths round alike.
// Per-(tile, Gaussian) slots are reduced per Gaussian in a fixed order, so the result is bitwise deterministic for
// any thread count.
#include "render/raster_isa.h"

#include <omp.h>

#include <algorithm>
#include <array>
#include <cstring>
#include <tuple>

#include "core/parallel.h"
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

// A tile's backward batch state in per-thread scratch: per batch BS packs [Tc, S, gr, gg, gb, gd, Tbg, GE[C],
// MW[J], GG[G * GWg]] (Tc the transmittance being rebuilt, S the sum behind it, the upstream gradients, Tbg =
// T_final (<bg, g_rgb> - g_alpha); the group gradient channels at GO) and each pixel's last contributor (last).
enum { bT, bS, bR, bG, bB, bD, bBg, kBatchFixed };
template <class T>
struct BackwardBatches {
  simd::Pack<T>* st;          // [kBatches, BS]
  simd::Mask<T>* last;        // [kBatches]
  int C, XS, J, GWg, BS, GO;  // extra channels and their row stride, pixel-weight maps, group gradient width
};

// One (tile, Gaussian) pair's gradient sums over its visits, lane by lane (dL/dpower terms before their scale).
template <class T>
struct PairSums {
  simd::Pack<T> mx, my, a, b, c, op, r, g, bl, z;
};

// The extra-channel and group upstream gradients and the pixel-weight maps of batch bt (pixels (py, px0 ..
// px0 + nvalid)), for the tile's groups glist [ng] only; jmask gets the maps present in the batch.
template <class T, int kX>
inline __attribute__((always_inline)) void load_batch_channels(const RasterInputs<T>& in, const RasterGrads<T>& g,
                                                               int W, int H, int py, int px0, int nvalid,
                                                               const int* glist, int ng, simd::Pack<T>* st,
                                                               const BackwardBatches<T>& b, uint32_t& jmask) {
  const int C = b.C, J = b.J, GWg = b.GWg, GO = b.GO;
  for (int c = 0; c < C + J; ++c) st[kBatchFixed + c] = simd::Pack<T>{};
  for (int u = 0; u < ng; ++u)
    for (int i = 0; i < GWg; ++i) st[GO + glist[u] * GWg + i] = simd::Pack<T>{};
  for (int l = 0; l < nvalid; ++l) {
    const size_t p = size_t(py) * W + px0 + l;
    if (kX != kNoChannels && g.d_extra)
      for (int c = 0; c < C; ++c) st[kBatchFixed + c][l] = g.d_extra[p * b.XS + c];
    if (kX != kNoChannels && ng > 0 && g.d_groups) {
      const T* dg = g.d_groups + p * size_t(g.d_group_row);
      for (int u = 0; u < ng; ++u) {
        const int gi = glist[u];
        for (int i = 0; i < GWg; ++i) st[GO + gi * GWg + i][l] = dg[size_t(gi) * g.d_group_stride + i];
      }
    }
  }
  if (J > 0) jmask |= load_batch_maps(in, J, W, H, py, px0, nvalid, st + kBatchFixed + C);
  if (kX != kNoChannels && ng > 0 && g.d_group_rows) {  // the batch's row of each of the tile's groups, on demand
    T row[kLanes * kMaxGroupGradWidth];
    for (int u = 0; u < ng; ++u) {
      const int gi = glist[u];
      g.d_group_rows(g.d_group_ctx, gi, py, px0, nvalid, row);
      for (int l = 0; l < nvalid; ++l)
        for (int i = 0; i < GWg; ++i) st[GO + gi * GWg + i][l] = row[l * GWg + i];
    }
  }
}

// Starts batch bt of the tile at (tx0, ty0) from forward's final T and last contributors and the upstream
// gradients (kmax: the batch's last contributor, jmask: its pixel-weight maps). Returns whether any of its
// pixels has a contributor (the batches the walk visits).
template <class T, bool kDepth, int kX>
inline __attribute__((always_inline)) bool start_backward_batch(const RasterInputs<T>& in, const Binning& bins,
                                                                const RasterGrads<T>& g, const T* final_T,
                                                                const int32_t* last, int tx0, int ty0, int bt,
                                                                const int* glist, int ng, const BackwardBatches<T>& b,
                                                                int& kmax, uint32_t& jmask) {
  using P = simd::Pack<T>;
  const int W = bins.width, H = bins.height;
  kmax = 0;
  jmask = 0;
  const int py = ty0 + bt / kBatchesPerRow, px0 = tx0 + (bt % kBatchesPerRow) * kLanes;
  if (py >= H || px0 >= W) return false;
  const int nvalid = std::min(kLanes, W - px0);
  P Tf = simd::splat(T(1)), gr = P{}, gg = P{}, gb = P{}, ga = P{}, gd = P{};
  simd::Mask<T> lastp = simd::Mask<T>{};
  for (int l = 0; l < nvalid; ++l) {
    const size_t p = size_t(py) * W + px0 + l;
    Tf[l] = final_T[p];
    lastp[l] = last[p];
    kmax = std::max(kmax, int(last[p]));
    if (g.d_rgb) {
      gr[l] = g.d_rgb[3 * p];
      gg[l] = g.d_rgb[3 * p + 1];
      gb[l] = g.d_rgb[3 * p + 2];
    }
    if (g.d_alpha) ga[l] = g.d_alpha[p];
    if (kDepth && g.d_depth) gd[l] = g.d_depth[p];
  }
  if (kmax == 0) return false;
  P* st = b.st + size_t(bt) * b.BS;
  load_batch_channels<T, kX>(in, g, W, bins.height, py, px0, nvalid, glist, ng, st, b, jmask);
  const T bg0 = in.background[0], bg1 = in.background[1], bg2 = in.background[2];
  st[bT] = Tf;
  st[bS] = P{};
  st[bR] = gr;
  st[bG] = gg;
  st[bB] = gb;
  st[bD] = gd;
  st[bBg] = Tf * (gr * bg0 + gg * bg1 + gb * bg2 - ga);
  b.last[bt] = lastp;
  return true;
}

// The visit-list path: <extra_k, g> (+ the groups' dots) of every (Gaussian, batch) visit of the walk, computed
// before it batch by batch (extra_dots, the batch's gradient packs in registers), visits in front-to-back
// order: batch bt's are entries [off[bt], off[bt] + cur[bt]) of the returned dots (the walk takes them from the
// back). Only the Gaussians before a batch's last contributor (kmax [kBatches]) visit it.
template <class T>
simd::Pack<T>* backward_visit_dots(const RasterInputs<T>& in, const Binning& bins, int tile, int n,
                                   typename RasterWorkspace<T>::PerThread& w, const uint32_t* masks, uint32_t live,
                                   const int* kmax, const BackwardBatches<T>& b, int* off, int* cur) {
  using P = simd::Pack<T>;
  const int GT = b.BS - b.GO;
  int vcnt[kBatches] = {};
  const auto [vk, vdot] = size_visit_lists<P>(w, masks, n, live, off);
  for (int k = 0; k < n; ++k)
    for (uint32_t mb = masks[k] & live; mb; mb &= mb - 1) {
      const int bt = __builtin_ctz(mb);
      if (k < kmax[bt]) vk[off[bt] + vcnt[bt]++] = bins.tile_gauss[bins.tile_start[tile] + k];
    }
  for (int bt = 0; bt < kBatches; ++bt) {
    cur[bt] = vcnt[bt];
    if (vcnt[bt] == 0) continue;
    const P* st = b.st + size_t(bt) * b.BS;
    extra_dots<T>(vk + off[bt], vcnt[bt], in.extra, b.C, b.XS, st + kBatchFixed, vdot + off[bt]);
    if (GT > 0) group_dots<T>(vk + off[bt], vcnt[bt], in, st + b.GO, vdot + off[bt]);
  }
  return vdot;
}

// <value, g> of one visit (batch state st): colour and depth, the extra channels and groups (precomputed in
// vdot, or folded: extra_dots + group_dots of the visit, in their order) and the pixel-weight maps present in
// the batch (jm; dw [J] the Gaussian's weight-sum gradients; one map, inside a hard object mask).
template <class T, bool kDepth, int kX>
inline __attribute__((always_inline)) simd::Pack<T> visit_dot(const RasterInputs<T>& in, const T* rc,
                                                              const FoldedGaussian<T, 3>& fg, const simd::Pack<T>* st,
                                                              const BackwardBatches<T>& b, simd::Pack<T> gr,
                                                              simd::Pack<T> gg, simd::Pack<T> gb, uint32_t jm,
                                                              const T* dw, const simd::Pack<T>* vdot) {
  using P = simd::Pack<T>;
  const int C = b.C, J = b.J, GT = b.BS - b.GO;
  P dot = rc[kCr] * gr + rc[kCg] * gg + rc[kCb] * gb;
  if (kDepth) dot += rc[kZ] * st[bD];
  if constexpr (kX == kVisitLists) dot += *vdot;
  if constexpr (kX == kFolded) {
    P vd = C > 0 ? extra_dot(fg.x, C, st + kBatchFixed) : P{};
    if (fg.one) {  // group_dot's sum
      const P* gs = st + b.GO + fg.slot;
      P d = P{};
      for (int i = 0; i < 3; ++i) d += fg.v[i] * gs[i];
      vd += d;
    } else if (GT > 0) {
      vd += group_dot(in, fg.e0, fg.e0 + fg.ne, b.GWg, st + b.GO);
    }
    dot += vd;
  }
  if (J > 0) {
    const P* sw = st + kBatchFixed + C;
    P d0 = P{};
    for_batch_maps(jm, J, [&](int jj) { d0 += dw[jj] * sw[jj]; });
    dot += d0;
  }
  return dot;
}

// The folded path's channel gradients of one visit (masked weight wm): ae [C] and ag [ne, GWg] get
// extra_grads' / group_grads' terms (kEntries false: the extra channels only; a Gaussian with more entries than
// ag holds takes its group gradients from its visit list, store_pair_grads).
template <class T, bool kEntries>
inline __attribute__((always_inline)) void add_folded_grads(const RasterInputs<T>& in, const FoldedGaussian<T, 3>& fg,
                                                            const simd::Pack<T>* st, const BackwardBatches<T>& b,
                                                            simd::Pack<T> wm, simd::Pack<T>* ae, simd::Pack<T>* ag) {
  const int GWg = b.GWg;
  for (int c = 0; c < b.C; ++c) ae[c] += wm * st[kBatchFixed + c];
  if (!kEntries) return;
  if (fg.one) {
    const simd::Pack<T>* gs = st + b.GO + fg.slot;
    for (int i = 0; i < 3; ++i) ag[i] += wm * gs[i];
  } else {
    for (int e = 0; e < fg.ne; ++e) {
      const simd::Pack<T>* gs = st + b.GO + size_t(in.group_id[fg.e0 + e]) * GWg;
      for (int i = 0; i < GWg; ++i) ag[e * GWg + i] += wm * gs[i];
    }
  }
}

// Gaussian k at batch bt, back to front: pixels before their last contributor (inr) with alpha >= kAlphaMin
// rebuild T_i = T_{i+1} / (1 - alpha), take dL/dalpha = T_i <value, g> - (S + Tbg) / (1 - alpha) and add
// w <value, g> to S; the pair's sums get the colour / depth / channel gradients (w g) and, where alpha is below
// the kAlphaMax clamp, the opacity, mean and conic gradients through dL/dpower. With kList (the visit-list path,
// and the folded one for a Gaussian with more than kFoldMaxEntries entries) the visit (batch, masked weight) is
// recorded in kvb / kvw for extra_grads / group_grads.
template <class T, bool kDepth, int kX, bool kList>
inline __attribute__((always_inline)) void backward_visit(const RasterInputs<T>& in, const T* rc, int k, int bt,
                                                          const FoldedGaussian<T, 3>& fg, const BackwardBatches<T>& b,
                                                          uint32_t jm, const T* dw, int tx0, int ty0,
                                                          const simd::Pack<T>* vdot, PairSums<T>& a, simd::Pack<T>* ae,
                                                          simd::Pack<T>* ag, int* kvb, simd::Pack<T>* kvw, int& nkv) {
  using P = simd::Pack<T>;
  using M = simd::Mask<T>;
  P* st = b.st + size_t(bt) * b.BS;
  const M inr = (M{} + MaskLane<T>(k)) < b.last[bt];
  const GaussianAtBatch<T> ev = eval_gaussian(rc, tx0, ty0, bt);
  const M c = inr & (ev.alpha >= T(kAlphaMin));
  if (!simd::any(c)) return;
  const P gr = st[bR], gg = st[bG], gb = st[bB];
  const P ioma = simd::vrecip(T(1) - ev.alpha);
  const P Ti = st[bT] * ioma;
  const P wgt = ev.alpha * Ti;
  const P dot = visit_dot<T, kDepth, kX>(in, rc, fg, st, b, gr, gg, gb, jm, dw, vdot);
  const P S = st[bS];
  P dLda = simd::fmadd(Ti, dot, -((S + st[bBg]) * ioma));  // one rounding in both channel paths
  st[bS] = c ? S + wgt * dot : S;
  st[bT] = c ? Ti : st[bT];
  const P wm = c ? wgt : P{};
  a.r += wm * gr;
  a.g += wm * gg;
  a.bl += wm * gb;
  if (kDepth) a.z += wm * st[bD];
  if constexpr (kList) {
    kvb[nkv] = bt;
    kvw[nkv++] = wm;
  }
  dLda = (c & (ev.araw < T(kAlphaMax))) ? dLda : P{};
  a.op += ev.gauss * dLda;
  const P pw = ev.araw * dLda;  // dL/dpower
  const P pdx = pw * ev.dx;
  a.mx += simd::fmadd(simd::splat(rc[kA]), pdx, ev.bdy * pw);  // as GCC contracts them, pinned (fmadd)
  a.my += simd::fmadd(simd::splat(rc[kB]), pdx, (rc[kC] * ev.dy) * pw);
  a.a += pdx * ev.dx;
  a.b += pdx * ev.dy;
  a.c += pw * (ev.dy * ev.dy);
  if constexpr (kX == kFolded) add_folded_grads<T, !kList>(in, fg, st, b, wm, ae, ag);
}

// Stores one pair's results: o [kNumGrads + C] (dpower/dmx = -(a dx + b dy), dpower/da = -dx^2 / 2, dpower/db =
// -dx dy, ...; the first 8 slots' lane sums at once, simd::hsum8, bitwise the 8 hsums, scaled as named; then the
// extra channels) and og [ne, GWg] its group gradients (visit-list path: from the visits kvb / kvw [nkv] of the
// batch state; folded: from ae / ag).
template <class T, bool kDepth, int kX>
inline __attribute__((always_inline)) void store_pair_grads(const RasterInputs<T>& in, const PairSums<T>& a,
                                                            const simd::Pack<T>* ae, const simd::Pack<T>* ag, int ne,
                                                            const int* kvb, const simd::Pack<T>* kvw, int nkv,
                                                            const BackwardBatches<T>& b, int gi, T* o, T* og) {
  using P = simd::Pack<T>;
  const int C = b.C, GWg = b.GWg;
  static_assert(gMx == 0 && gMy == 1 && gA == 2 && gB == 3 && gC == 4 && gOp == 5 && gR == 6 && gG == 7);
  const P acc[8] = {a.mx, a.my, a.a, a.b, a.c, a.op, a.r, a.g};
  const P sums = simd::hsum8(acc) * P{T(-1), T(-1), T(-0.5), T(-1), T(-0.5), T(1), T(1), T(1)};
  std::memcpy(o, &sums, sizeof(sums));
  o[gBl] = simd::hsum<T>(a.bl);
  o[gZ] = kDepth ? simd::hsum<T>(a.z) : T(0);
  if constexpr (kX == kVisitLists) {
    extra_grads<T>(kvb, kvw, nkv, b.st + kBatchFixed, b.BS, C, o + kNumGrads);
  } else if constexpr (kX == kFolded) {
    for (int c = 0; c < C; ++c) o[kNumGrads + c] = simd::hsum<T>(ae[c]);
  } else {
    for (int ch = 0; ch < C; ++ch) o[kNumGrads + ch] = T(0);
  }
  if (kX != kNoChannels && og) {
    if constexpr (kX == kVisitLists) {
      group_grads<T>(kvb, kvw, nkv, b.st + b.GO, b.BS, in, gi, og);
    } else if constexpr (kX == kFolded) {
      if (ne > kFoldMaxEntries) group_grads<T>(kvb, kvw, nkv, b.st + b.GO, b.BS, in, gi, og);
      else
        for (int i = 0; i < ne * GWg; ++i) og[i] = simd::hsum<T>(ag[i]);
    }
  }
}

// Gaussian k of the tile, back to front over the batches mb of its mask (each only before its last
// contributor, kmax [kBatches]), its gradient sums in registers, stored once for the pair (o, og: its slots).
template <class T, bool kDepth, int kX>
inline __attribute__((always_inline)) void backward_gaussian(const RasterInputs<T>& in, const T* rc, int k, int gi,
                                                             const T* cr, const BackwardBatches<T>& b, const int* kmax,
                                                             const uint32_t* jmask, const T* dw, int tx0, int ty0,
                                                             uint32_t mb, const int* voff, int* vcur,
                                                             const simd::Pack<T>* vdot, T* o, T* og) {
  using P = simd::Pack<T>;
  const int C = b.C, GWg = b.GWg, GT = b.BS - b.GO;
  PairSums<T> a{};
  // Folded channels: the Gaussian's extra row and group entries (its channel record cr); their gradient sums
  // (ae, ag) on the stack.
  FoldedGaussian<T, 3> fg;
  load_folded<T, 3>(rc, cr, kX == kFolded ? C : 0, kX == kFolded && GT > 0, GWg, fg);
  P ae[kFoldMaxChannels], ag[kFoldMaxEntries * kFoldMaxWidth];
  if constexpr (kX == kFolded) {
    for (int c = 0; c < C; ++c) ae[c] = P{};
    if (fg.ne <= kFoldMaxEntries)
      for (int i = 0; i < fg.ne * GWg; ++i) ag[i] = P{};
  }
  int kvb[kBatches];  // visit lists (and a folded Gaussian with many entries): its visits, batch and masked weight
  P kvw[kBatches];
  int nkv = 0;
  auto walk = [&]<bool kList>() {
    while (mb) {
      const int bt = __builtin_ctz(mb);
      mb &= mb - 1;
      if (k >= kmax[bt]) continue;
      const P* vd = kX == kVisitLists ? vdot + voff[bt] + --vcur[bt] : nullptr;  // this visit's (lists walked back)
      backward_visit<T, kDepth, kX, kList>(in, rc, k, bt, fg, b, jmask[bt], dw, tx0, ty0, vd, a, ae, ag, kvb, kvw, nkv);
    }
  };
  if (kX == kFolded && fg.ne > kFoldMaxEntries) walk.template operator()<true>();  // rare: its own visit list
  else walk.template operator()<kX == kVisitLists>();
  store_pair_grads<T, kDepth, kX>(in, a, ae, ag, fg.ne, kvb, kvw, nkv, b, gi, o, og);
}

// Backward of one tile, Gaussian-major: the tile's Gaussians are walked back to front (k = n-1 .. 0); each visits
// the batches its mask names, whose per-pixel state (T, S) lives in per-thread scratch, while its gradient
// sums stay in registers and are stored once per (tile, Gaussian) pair.
template <class T, bool kDepth, int kX>
void backward_tile(const RasterInputs<T>& in, const Binning& bins, int tile, typename RasterWorkspace<T>::PerThread& w,
                   const T* final_T, const int32_t* last, const RasterGrads<T>& g, const T* records, const T* chan,
                   T* tile_records, const uint32_t* ws_masks, T* pair_grad, const size_t* pair_gslot, T* pair_group) {
  using P = simd::Pack<T>;
  using M = simd::Mask<T>;
  const int C = in.num_extra, XS = in.extra_stride > 0 ? in.extra_stride : C, F = kNumGrads + C;
  const int* gauss = bins.tile_gauss.data() + bins.tile_start[tile];                    // [n] the tile's Gaussians
  const int GWg = g.group_grads() ? in.group_grad_width : 0, GT = in.num_groups * GWg;  // group gradient channels
  const auto [tx0, ty0] = tile_origin(bins, tile);
  TileData<T> td;
  if (!load_records(bins, records, tile_records, false, tile, td)) return;
  const int n = td.n, s = bins.tile_start[tile];
  const uint32_t* masks = ws_masks + s;
  const int J = g.d_weight_sums ? in.num_weights : 0;
  T* DW = J > 0 ? w.dw.template get<T>(size_t(n) * J) : nullptr;  // [n, J] the weight-sum gradients, tile order
  for (int k = 0; k < n && J > 0; ++k)
    for (int jj = 0; jj < J; ++jj) DW[size_t(k) * J + jj] = g.d_weight_sums[size_t(bins.tile_gauss[s + k]) * J + jj];
  BackwardBatches<T> b{nullptr, nullptr, C, XS, J, GWg, kBatchFixed + C + J + GT, kBatchFixed + C + J};
  b.st = w.bstate.template get<P>(size_t(kBatches) * b.BS);
  b.last = w.blast.template get<M>(kBatches);
  // The groups the tile's Gaussians have entries in: only their upstream gradients are loaded (no Gaussian of
  // the tile reads another group's).
  int ng = 0;
  const int* glist = nullptr;
  if (kX != kNoChannels && GT > 0) {
    const TileGroupList tg = tile_group_list(in, td, gauss, kX == kFolded ? chan : nullptr, w.groups);
    glist = tg.list;
    ng = tg.count;
  }
  int kmax[kBatches];
  uint32_t jmask[kBatches];  // pixel-weight maps present in each batch (for_batch_maps)
  uint32_t live = 0;         // batches with at least one contributor
  for (int bt = 0; bt < kBatches; ++bt)
    if (start_backward_batch<T, kDepth, kX>(in, bins, g, final_T, last, tx0, ty0, bt, glist, ng, b, kmax[bt],
                                            jmask[bt]))
      live |= 1u << bt;
  int voff[kBatches + 1], vcur[kBatches];
  P* vdot = nullptr;
  if (kX == kVisitLists) vdot = backward_visit_dots(in, bins, tile, n, w, masks, live, kmax, b, voff, vcur);
  for (int k = n - 1; k >= 0; --k) {
    T* o = pair_grad + size_t(bins.tile_pair[s + k]) * F;
    T* og = kX != kNoChannels && GT > 0 ? pair_group + pair_gslot[s + k] : nullptr;
    const T* cr = kX == kFolded ? chan + size_t(gauss[k]) * kChanRecord : nullptr;
    const int gi = kX != kNoChannels && GT > 0 ? gauss[k] : 0;
    backward_gaussian<T, kDepth, kX>(in, td.rec + size_t(k) * kRecord, k, gi, cr, b, kmax, jmask,
                                     J > 0 ? DW + size_t(k) * J : nullptr, tx0, ty0, masks[k] & live, voff, vcur, vdot,
                                     o, og);
  }
}

// The group-gradient slots (groups with GWg gradient channels): each Gaussian's, one slot of entries x GWg per
// pair, Gaussian-major (ws.group_off [n + 1] their offsets in ws.pair_group), and each pair's slot in tile order
// (ws.pair_gslot [pairs]: the walks write them without looking up its Gaussian).
template <class T>
void group_slots(const RasterInputs<T>& in, const Binning& bins, int GWg, RasterWorkspace<T>& ws) {
  const int n = in.n;
  ws.group_off.resize(size_t(n) + 1);
  if (ws.slot_rule.size() < size_t(n)) ws.slot_rule.resize(size_t(n));
  size_t* GOF = ws.group_off.data();
  // Each Gaussian's rule in 16 bytes (slot of its pair p = base + p * width, with base = its first slot - its first
  // pair * width, modulo 2^64), so that the pass over the pairs in tile order reads one random 16 bytes per pair
  // instead of group_off, pair_offset and group_ptr (three lines).
  std::array<size_t, 2>* rule = ws.slot_rule.data();
  auto width = [&](int i) { return size_t(in.group_ptr[i + 1] - in.group_ptr[i]) * GWg; };
  auto slots = [&](int i) { return size_t(bins.pair_offset[i + 1] - bins.pair_offset[i]) * width(i); };
  // group_off, the running sum of the Gaussians' slots, on the threads (it was a serial pass), and the rules.
  parallel_offsets(n, GOF, slots, [&](int i, size_t off) {
    rule[i] = {off - size_t(bins.pair_offset[i]) * width(i), width(i)};
  });
  if (ws.pair_group.size() < GOF[n]) ws.pair_group.resize(GOF[n]);
  if (ws.pair_gslot.size() < size_t(bins.num_pairs)) ws.pair_gslot.resize(size_t(bins.num_pairs));
  size_t* slot = ws.pair_gslot.data();
#pragma omp parallel for schedule(static)
  for (int t = 0; t < bins.num_pairs; ++t) {
    const std::array<size_t, 2> r = rule[bins.tile_gauss[t]];
    slot[t] = r[0] + size_t(bins.tile_pair[t]) * r[1];
  }
}

// Gaussian i's gradients: the sums of its pair slots in pair order (pg [pairs, F], F = kNumGrads + C; its group
// slots in pgr from gof [n + 1] when `groups`), so the result does not depend on the thread count.
template <class T>
inline __attribute__((always_inline)) void reduce_pairs(const RasterInputs<T>& in, const Binning& bins,
                                                        const RasterGrads<T>& g, int i, int C, int XS, int GWg,
                                                        bool groups, const T* pg, const T* pgr, const size_t* gof) {
  const int F = kNumGrads + C, GW = in.group_width;
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
        const T* o = pgr + gof[i] + size_t(p - bins.pair_offset[i]) * ne * GWg;
        for (int e = 0; e < ne; ++e)
          for (int c = 0; c < GWg; ++c) gv[size_t(e) * GW + c] += o[e * GWg + c];
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
  const int GWg = g.group_grads() ? in.group_grad_width : 0;
  const bool groups = in.num_groups > 0 && GWg > 0;
  const bool ext = (C > 0 && g.d_extra != nullptr) || groups;
  if (ws.pair_grad.size() < size_t(bins.num_pairs) * F) ws.pair_grad.resize(size_t(bins.num_pairs) * F);
  if (groups) group_slots(in, bins, GWg, ws);
  const int x = ext ? channel_path(in, C, groups ? in.num_groups * GWg : 0, GWg) : kNoChannels;
  const size_t* GOF = groups ? ws.group_off.data() : nullptr;
  const size_t* GSL = groups ? ws.pair_gslot.data() : nullptr;
  T* PGR = groups ? ws.pair_group.data() : nullptr;
  T* pg = ws.pair_grad.data();
  const uint32_t* MK = ws.masks.data();
  const T* R = ws.records.data();
  // Forward's channel records; built here when forward did not fold (another call's settings).
  const T* CR = x != kFolded ? nullptr : ws.chan_n == in.n ? ws.chan_records.data() : fill_chan_records(in, ws);
  T* TR = ws.tile_records.data();
  const int run = tile_run(bins.num_tiles);
#pragma omp parallel
  {
    auto& w = ws.threads[omp_get_thread_num()];
#pragma omp for schedule(dynamic, run)
    for (int t = 0; t < bins.num_tiles; ++t) {
      if (dep && x == kVisitLists)
        backward_tile<T, true, kVisitLists>(in, bins, t, w, final_T, last, g, R, CR, TR, MK, pg, GSL, PGR);
      else if (dep && x == kFolded)
        backward_tile<T, true, kFolded>(in, bins, t, w, final_T, last, g, R, CR, TR, MK, pg, GSL, PGR);
      else if (dep) backward_tile<T, true, kNoChannels>(in, bins, t, w, final_T, last, g, R, CR, TR, MK, pg, GSL, PGR);
      else if (x == kVisitLists)
        backward_tile<T, false, kVisitLists>(in, bins, t, w, final_T, last, g, R, CR, TR, MK, pg, GSL, PGR);
      else if (x == kFolded)
        backward_tile<T, false, kFolded>(in, bins, t, w, final_T, last, g, R, CR, TR, MK, pg, GSL, PGR);
      else backward_tile<T, false, kNoChannels>(in, bins, t, w, final_T, last, g, R, CR, TR, MK, pg, GSL, PGR);
    }
    // reduce pair slots per Gaussian in a fixed order
#pragma omp for schedule(static)
    for (int i = 0; i < in.n; ++i) reduce_pairs(in, bins, g, i, C, XS, GWg, groups, pg, PGR, GOF);
  }
}

template void rasterize_backward<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                        const float*, const int32_t*, const RasterGrads<float>&);
template void rasterize_backward<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                         const double*, const int32_t*, const RasterGrads<double>&);

}  // namespace hgs::render::HGS_RASTER_NS

#include "render/raster_isa_end.h"
