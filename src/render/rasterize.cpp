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

// Structure-of-arrays fields of a tile's Gaussians.
enum Field { kMx, kMy, kHa, kB, kHc, kA, kC, kOp, kCr, kCg, kCb, kZ, kNumFields };
// Backward accumulator slots per Gaussian (and per pair); extras follow.
enum Grad { gMx, gMy, gA, gB, gC, gOp, gR, gG, gBl, gZ, kNumGrads };

template <class T>
struct TileData {
  int n = 0, cap = 0, C = 0;
  const T* f[kNumFields];
  const T* extra = nullptr;  // [n, C]
  const int* lists = nullptr;
  int count[kBatches];
};

// Loads the tile's Gaussians into SoA scratch and builds the 32 batch lists. Returns false for an empty tile.
template <class T>
bool load_tile(const RasterInputs<T>& in, const Binning& bins, int tile, typename RasterWorkspace<T>::PerThread& w,
               TileData<T>& td) {
  const int s = bins.tile_start[tile], e = bins.tile_start[tile + 1];
  const int n = e - s;
  td.n = n;
  td.C = in.num_extra;
  if (n == 0) return false;
  const int C = in.num_extra;
  const int cap = (n + 7) & ~7;
  td.cap = cap;
  if (w.soa.size() < size_t(cap) * (kNumFields + C)) w.soa.resize(size_t(cap) * (kNumFields + C));
  if (w.lists.size() < size_t(kBatches) * n) w.lists.resize(size_t(kBatches) * n);
  if (w.ibuf.size() < size_t(4) * n) w.ibuf.resize(size_t(4) * n);
  T* soa = w.soa.data();
  T* f[kNumFields];
  for (int k = 0; k < kNumFields; ++k) {
    f[k] = soa + size_t(k) * cap;
    td.f[k] = f[k];
  }
  T* ex = soa + size_t(kNumFields) * cap;
  td.extra = ex;
  const int tx0 = (tile % bins.tiles_x) * kTileSize, ty0 = (tile / bins.tiles_x) * kTileSize;
  int* lists = w.lists.data();
  td.lists = lists;
  for (int b = 0; b < kBatches; ++b) td.count[b] = 0;
  const int ymax = std::min(ty0 + kTileSize, bins.height) - 1;
  for (int k = 0; k < n; ++k) {
    const int g = bins.tile_gauss[s + k];
    f[kMx][k] = in.mean2d[2 * g];
    f[kMy][k] = in.mean2d[2 * g + 1];
    const T a = in.conic[3 * g], b = in.conic[3 * g + 1], c = in.conic[3 * g + 2];
    f[kHa][k] = T(0.5) * a;
    f[kB][k] = b;
    f[kHc][k] = T(0.5) * c;
    f[kA][k] = a;
    f[kC][k] = c;
    f[kOp][k] = in.opacity[g];
    f[kCr][k] = in.color[3 * g];
    f[kCg][k] = in.color[3 * g + 1];
    f[kCb][k] = in.color[3 * g + 2];
    f[kZ][k] = in.depth ? in.depth[g] : T(0);
    for (int c2 = 0; c2 < C; ++c2) ex[size_t(k) * C + c2] = in.extra[size_t(g) * C + c2];
    const int* bb = &bins.bbox[4 * size_t(g)];
    const int y0 = std::max(bb[2], ty0), y1 = std::min(bb[3], ymax);
    for (int y = y0; y <= y1; ++y) {
      const int row = y - ty0;
      for (int h = 0; h < kBatchesPerRow; ++h) {
        const int xs = tx0 + h * kLanes;
        if (bb[0] <= xs + kLanes - 1 && bb[1] >= xs) {
          const int bt = row * kBatchesPerRow + h;
          lists[size_t(bt) * n + td.count[bt]++] = k;
        }
      }
    }
  }
  return true;
}

template <class T, bool kDepth, bool kExtra>
void forward_tile(const RasterInputs<T>& in, const Binning& bins, int tile, typename RasterWorkspace<T>::PerThread& w,
                  const RasterOutputs<T>& out) {
  using P = simd::Pack<T>;
  using M = simd::Mask<T>;
  using I = typename std::remove_reference<decltype(M{}[0])>::type;
  const int W = bins.width, H = bins.height, C = in.num_extra;
  const int tx0 = (tile % bins.tiles_x) * kTileSize, ty0 = (tile / bins.tiles_x) * kTileSize;
  TileData<T> td;
  const bool any_g = load_tile(in, bins, tile, w, td);
  if (kExtra && w.chan.size() < size_t(C)) w.chan.resize(size_t(C));
  P* E = w.chan.data();
  const P lane = simd::iota_pack<T>();
  M lane_i = __builtin_convertvector(lane, M);
  const T bg0 = in.background[0], bg1 = in.background[1], bg2 = in.background[2];
  for (int bt = 0; bt < kBatches; ++bt) {
    const int py = ty0 + bt / kBatchesPerRow, px0 = tx0 + (bt % kBatchesPerRow) * kLanes;
    if (py >= H || px0 >= W) continue;
    const int nvalid = std::min(kLanes, W - px0);
    M active = lane_i < I(nvalid);
    const P fx = lane + (T(px0) + T(0.5));
    const T fy = T(py) + T(0.5);
    P Tr = simd::splat(T(1)), R = P{}, G = P{}, B = P{}, D = P{};
    M lastp = M{};
    if (kExtra)
      for (int c = 0; c < C; ++c) E[c] = P{};
    const int cnt = any_g ? td.count[bt] : 0;
    const int* list = any_g ? td.lists + size_t(bt) * td.n : nullptr;
    for (int j = 0; j < cnt; ++j) {
      const int k = list[j];
      const T dy = td.f[kMy][k] - fy;
      const P dx = td.f[kMx][k] - fx;
      const T bdy = td.f[kB][k] * dy, hcdy2 = td.f[kHc][k] * dy * dy;
      const P power = -(dx * (td.f[kHa][k] * dx + bdy) + hcdy2);
      const P alpha = simd::vmin<T>(td.f[kOp][k] * simd::vexp(power), simd::splat(T(0.99)));
      const M valid = active & (alpha >= T(1.0 / 255.0));
      const P testT = Tr * (T(1) - alpha);
      const M stop = valid & (testT < T(1e-4));
      active = active & ~stop;
      const M acc = valid & ~stop;
      const P wgt = acc ? alpha * Tr : P{};
      R += wgt * td.f[kCr][k];
      G += wgt * td.f[kCg][k];
      B += wgt * td.f[kCb][k];
      if (kDepth) D += wgt * td.f[kZ][k];
      if (kExtra) {
        const T* e = td.extra + size_t(k) * C;
        for (int c = 0; c < C; ++c) E[c] += wgt * e[c];
      }
      Tr = acc ? testT : Tr;
      lastp = acc ? M{} + I(j + 1) : lastp;
      if (!simd::any(active)) break;
    }
    for (int l = 0; l < nvalid; ++l) {
      const size_t p = size_t(py) * W + px0 + l;
      out.rgb[3 * p] = R[l] + Tr[l] * bg0;
      out.rgb[3 * p + 1] = G[l] + Tr[l] * bg1;
      out.rgb[3 * p + 2] = B[l] + Tr[l] * bg2;
      out.alpha[p] = T(1) - Tr[l];
      out.final_T[p] = Tr[l];
      out.last[p] = int32_t(lastp[l]);
      if (kDepth) out.depth[p] = D[l];
      if (kExtra)
        for (int c = 0; c < C; ++c) out.extra[p * C + c] = E[c][l];
    }
  }
}

template <class T, bool kDepth, bool kExtra>
void backward_tile(const RasterInputs<T>& in, const Binning& bins, int tile,
                   typename RasterWorkspace<T>::PerThread& w, const T* final_T, const int32_t* last,
                   const RasterGrads<T>& g, T* pair_grad) {
  using P = simd::Pack<T>;
  using M = simd::Mask<T>;
  using I = typename std::remove_reference<decltype(M{}[0])>::type;
  const int W = bins.width, H = bins.height, C = in.num_extra;
  const int F = kNumGrads + C;
  const int tx0 = (tile % bins.tiles_x) * kTileSize, ty0 = (tile / bins.tiles_x) * kTileSize;
  TileData<T> td;
  if (!load_tile(in, bins, tile, w, td)) return;
  const int n = td.n;
  if (w.acc.size() < size_t(n) * F) w.acc.resize(size_t(n) * F);
  P* acc = w.acc.data();
  std::fill(acc, acc + size_t(n) * F, P{});
  if (kExtra && w.chan.size() < size_t(C)) w.chan.resize(size_t(C));
  P* GE = w.chan.data();
  const P lane = simd::iota_pack<T>();
  const T bg0 = in.background[0], bg1 = in.background[1], bg2 = in.background[2];
  for (int bt = 0; bt < kBatches; ++bt) {
    const int py = ty0 + bt / kBatchesPerRow, px0 = tx0 + (bt % kBatchesPerRow) * kLanes;
    if (py >= H || px0 >= W) continue;
    const int nvalid = std::min(kLanes, W - px0);
    P Tf = simd::splat(T(1)), gr = P{}, gg = P{}, gb = P{}, ga = P{}, gd = P{};
    M lastp = M{};
    if (kExtra)
      for (int c = 0; c < C; ++c) GE[c] = P{};
    int jmax = 0;
    for (int l = 0; l < nvalid; ++l) {
      const size_t p = size_t(py) * W + px0 + l;
      Tf[l] = final_T[p];
      lastp[l] = last[p];
      jmax = std::max(jmax, int(last[p]));
      if (g.d_rgb) {
        gr[l] = g.d_rgb[3 * p];
        gg[l] = g.d_rgb[3 * p + 1];
        gb[l] = g.d_rgb[3 * p + 2];
      }
      if (g.d_alpha) ga[l] = g.d_alpha[p];
      if (kDepth && g.d_depth) gd[l] = g.d_depth[p];
      if (kExtra && g.d_extra)
        for (int c = 0; c < C; ++c) GE[c][l] = g.d_extra[p * C + c];
    }
    if (jmax == 0) continue;
    const P Tbg = Tf * (gr * bg0 + gg * bg1 + gb * bg2 - ga);
    const P fx = lane + (T(px0) + T(0.5));
    const T fy = T(py) + T(0.5);
    P S = P{}, Tc = Tf;
    const int* list = td.lists + size_t(bt) * n;
    for (int j = jmax - 1; j >= 0; --j) {
      const int k = list[j];
      const M inr = (M{} + I(j)) < lastp;
      const T dy = td.f[kMy][k] - fy;
      const P dx = td.f[kMx][k] - fx;
      const T bdy = td.f[kB][k] * dy, hcdy2 = td.f[kHc][k] * dy * dy;
      const P power = -(dx * (td.f[kHa][k] * dx + bdy) + hcdy2);
      const P gauss = simd::vexp(power);
      const P araw = td.f[kOp][k] * gauss;
      const P alpha = simd::vmin<T>(araw, simd::splat(T(0.99)));
      const M c = inr & (alpha >= T(1.0 / 255.0));
      if (!simd::any(c)) continue;
      const P ioma = T(1) / (T(1) - alpha);
      const P Ti = Tc * ioma;
      const P wgt = alpha * Ti;
      P dot = td.f[kCr][k] * gr + td.f[kCg][k] * gg + td.f[kCb][k] * gb;
      if (kDepth) dot += td.f[kZ][k] * gd;
      const T* e = kExtra ? td.extra + size_t(k) * C : nullptr;
      if (kExtra)
        for (int ch = 0; ch < C; ++ch) dot += e[ch] * GE[ch];
      P dLda = Ti * dot - (S + Tbg) * ioma;
      S = c ? S + wgt * dot : S;
      Tc = c ? Ti : Tc;
      const P wm = c ? wgt : P{};
      P* a = acc + size_t(k) * F;
      a[gR] += wm * gr;
      a[gG] += wm * gg;
      a[gBl] += wm * gb;
      if (kDepth) a[gZ] += wm * gd;
      if (kExtra)
        for (int ch = 0; ch < C; ++ch) a[kNumGrads + ch] += wm * GE[ch];
      dLda = (c & (araw < T(0.99))) ? dLda : P{};
      a[gOp] += gauss * dLda;
      const P pw = araw * dLda;  // dL/dpower
      const P pdx = pw * dx;
      a[gMx] += td.f[kA][k] * pdx + bdy * pw;
      a[gMy] += td.f[kB][k] * pdx + (td.f[kC][k] * dy) * pw;
      a[gA] += pdx * dx;
      a[gB] += pdx * dy;
      a[gC] += pw * (dy * dy);
    }
  }
  // per-pair results (dpower/dmx = -(a dx + b dy), dpower/da = -dx^2 / 2, dpower/db = -dx dy, ...)
  const int s = bins.tile_start[tile];
  for (int k = 0; k < n; ++k) {
    const P* a = acc + size_t(k) * F;
    T* o = pair_grad + size_t(bins.tile_pair[s + k]) * F;
    o[gMx] = -simd::hsum<T>(a[gMx]);
    o[gMy] = -simd::hsum<T>(a[gMy]);
    o[gA] = T(-0.5) * simd::hsum<T>(a[gA]);
    o[gB] = -simd::hsum<T>(a[gB]);
    o[gC] = T(-0.5) * simd::hsum<T>(a[gC]);
    o[gOp] = simd::hsum<T>(a[gOp]);
    o[gR] = simd::hsum<T>(a[gR]);
    o[gG] = simd::hsum<T>(a[gG]);
    o[gBl] = simd::hsum<T>(a[gBl]);
    o[gZ] = kDepth ? simd::hsum<T>(a[gZ]) : T(0);
    for (int ch = 0; ch < C; ++ch) o[kNumGrads + ch] = simd::hsum<T>(a[kNumGrads + ch]);
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
#pragma omp parallel
  {
    auto& w = ws.threads[omp_get_thread_num()];
#pragma omp for schedule(dynamic, 1)
    for (int t = 0; t < bins.num_tiles; ++t) {
      if (dep && ext) forward_tile<T, true, true>(in, bins, t, w, out);
      else if (dep) forward_tile<T, true, false>(in, bins, t, w, out);
      else if (ext) forward_tile<T, false, true>(in, bins, t, w, out);
      else forward_tile<T, false, false>(in, bins, t, w, out);
    }
  }
}

template <class T>
void rasterize_backward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws, const T* final_T,
                        const int32_t* last, const RasterGrads<T>& g) {
  ensure_threads(ws);
  const int C = in.num_extra, F = kNumGrads + C;
  const bool dep = in.depth != nullptr && g.d_depth != nullptr;
  const bool ext = C > 0 && g.d_extra != nullptr;
  if (ws.pair_grad.size() < size_t(bins.num_pairs) * F) ws.pair_grad.resize(size_t(bins.num_pairs) * F);
  T* pg = ws.pair_grad.data();
  if (!ext && C > 0) {
    // extra slots are not written by the kernel in this case; keep them zero
    std::fill(pg, pg + size_t(bins.num_pairs) * F, T(0));
  }
#pragma omp parallel
  {
    auto& w = ws.threads[omp_get_thread_num()];
#pragma omp for schedule(dynamic, 1)
    for (int t = 0; t < bins.num_tiles; ++t) {
      if (dep && ext) backward_tile<T, true, true>(in, bins, t, w, final_T, last, g, pg);
      else if (dep) backward_tile<T, true, false>(in, bins, t, w, final_T, last, g, pg);
      else if (ext) backward_tile<T, false, true>(in, bins, t, w, final_T, last, g, pg);
      else backward_tile<T, false, false>(in, bins, t, w, final_T, last, g, pg);
    }
    // reduce pair slots per Gaussian in a fixed order
#pragma omp for schedule(static)
    for (int i = 0; i < in.n; ++i) {
      T s[kNumGrads] = {};
      T* gex = g.extra ? g.extra + size_t(i) * C : nullptr;
      if (gex)
        for (int ch = 0; ch < C; ++ch) gex[ch] = 0;
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
