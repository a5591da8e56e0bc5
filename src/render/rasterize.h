// Per-pixel front-to-back alpha compositing over 16x16 tiles (3DGS semantics), forward and exact backward.
//
// Pixel p (centre (x + 0.5, y + 0.5)) walks its tile's list in (depth, index) order:
//   d = mean2d - p, alpha = min(0.99, opacity * exp(-0.5 d^T conic d)); skip when alpha < 1/255;
//   stop (without accumulating) when T * (1 - alpha) < 1e-4; otherwise w = alpha T, accumulate w * (colour,
//   depth, extra) and T *= 1 - alpha. rgb = sum + T_final * background, alpha = 1 - T_final.
// Layout for speed: each tile's Gaussians are copied once into contiguous 16-scalar records; the tile is cut
// into 32 batches of 8 pixels (half a row, one AVX2 register of floats) and every Gaussian gets a 32-bit mask
// of the batches its alpha >= 1/255 region (exact per-row interval of the ellipse) touches. Forward walks the
// Gaussians front to back (Gaussian-major), updating only the batches in its mask that still have a live pixel,
// per-batch accumulators in per-thread scratch; a batch drops out when all 8 pixels stopped, the tile ends when
// no batch is left. Pixel decisions are exactly the per-pixel 3DGS loop's.
// Backward walks the tile's Gaussians back to front (Gaussian-major again: each visits the batches of its mask,
// per-batch pixel state in scratch, its gradient sums in registers), starting at each pixel's last contributor.
// It rebuilds T_i = T_{i+1} / (1 - alpha_i) from the saved final T and keeps one scalar per pixel,
// S = sum_{j>i} w_j <value_j, dL/dout>, so dL/dalpha_i = T_i <value_i, g> - (S + T_final (<bg, g_rgb> - g_alpha))
// / (1 - alpha_i) for any number of channels. Optional pixel-weight maps M_j give per-Gaussian sums
// a_{n,j} = sum_p M_j(p) alpha_n(p) T_n(p) (the blending weight a Gaussian receives inside mask j); their
// gradient enters S and <value, g> as the per-pixel value sum_j dL/da_{n,j} M_j(p).
// Sparse channel groups (e.g. the hybrid method's object channels, where a Gaussian belongs to one or two of K
// objects): a Gaussian adds its value rows to its own groups only, at a cost per visit of its entries instead of
// all G * GW channels.
// Extra channels and groups take one of two paths (ChannelPath). Many channels (C > 4, e.g. the dense object
// layout or the no-SCL ablation's language channels) are kept out of the walks, which would read-modify-write C
// packs of batch state per visit: forward records each batch's visits (Gaussian, weight pack) and then sums
// w * extra per batch, 12 channels at a time in registers; backward computes every visit's <extra, dL/dextra>
// batch by batch before its walk (the walk needs it only as one number per pixel) and, after each Gaussian's
// visits, its channel gradients sum_visits w * dL/dextra the same way ("visit lists"). A few (C <= 4, e.g. the
// hybrid method's base render) and the groups are folded into the walks: each visit adds w * value to the
// batch's channel state and, backward, the value's dot with the batch's gradient to <value, g> and w * g to the
// Gaussian's gradient sums (on the stack; a Gaussian with more than 4 group entries keeps a list of its own
// visits instead and sums its group gradients from it), with no lists to write and read back. Both paths sum the same
// terms in the same order: bitwise-equal results (test_groups.cpp). Pixel-weight maps are visited only where they are
// non-zero in a batch (with hard object masks, one map per batch); forward, a Gaussian's sums are reduced to
// scalars as its walk in a tile ends, for those maps only, and written to their pair after the tile's walk (the
// sum over a Gaussian's pairs adds only the maps each pair reached: the others are +0).
// Gradients of a (tile, Gaussian) pair are stored in that pair's slot and the slots are reduced per Gaussian in a
// fixed order, so results are bitwise deterministic for any thread count and schedule. Parallel over tiles with
// OpenMP (dynamic schedule, runs of neighbouring tiles per chunk: detail::tile_run); all scratch lives in
// RasterWorkspace (no allocation once warm), the per-Gaussian and per-pair records each in a cache line of its own.
// Everything is templated on the scalar (float in production, double in the tests). Kernels:
// rasterize_forward.cpp and rasterize_backward.cpp (shared internals in rasterize_common.h, the batch masks in
// rasterize_masks.h); rasterize_pixels.cpp, the forward's alpha and depth at chosen pixels only
// (rasterize_depth_at).
#pragma once
#include <array>
#include <cstddef>
#include <cstdint>
#include <new>
#include <vector>

#include "render/binning.h"

namespace hgs::render {

// The 3DGS cut-offs above, shared by rasterize_forward.cpp, rasterize_backward.cpp and binning.cpp.
constexpr double kAlphaMax = 0.99;                    // alpha = min(kAlphaMax, ...), no gradient through the clamp
constexpr double kAlphaMinInverse = 255.0;            // binning tests opacity * 255 >= 1 and ln(255 opacity)
constexpr double kAlphaMin = 1.0 / kAlphaMinInverse;  // a Gaussian is skipped at a pixel when alpha < 1/255
constexpr double kTransmittanceMin = 1e-4;            // a pixel stops when T * (1 - alpha) < 1e-4

// How extra channels and groups are composited and differentiated: kAuto folds a few dense channels (at most 4)
// and groups into the walks and keeps more channels out of them (visit lists; the top of this file); the others
// force one (benchmarks, tests; kFolded where allowed). Both give the same values.
enum class ChannelPath { kAuto, kVisitLists, kFolded };

template <class T>
struct RasterInputs {
  int width = 0, height = 0, n = 0;
  const T* mean2d = nullptr;   // [N, 2] pixels
  const T* conic = nullptr;    // [N, 3] (a, b, c) of [[a, b], [b, c]]
  const T* opacity = nullptr;  // [N] in (0, 1)
  const T* color = nullptr;    // [N, 3]
  const T* depth = nullptr;    // [N] camera-space depth; null = no depth channel
  const T* extra = nullptr;    // [N, XS]; null when num_extra = 0
  int num_extra = 0;           // C: channels composited (forward) or differentiated (backward)
  int extra_stride = 0;        // XS >= C: row stride of extra, d_extra and the extra gradient (0 = C); backward
                               // writes zero gradients for channels [C, XS)
  T background[3] = {0, 0, 0};
  const float* pixel_weights = nullptr;  // [J, H, W] optional per-pixel weight maps M_j (planar)
  int num_weights = 0;                   // J
  // Or the maps as one label image: M_j(p) = 1 where pixel_labels[p] == label_ids[j], else 0 (used instead of
  // pixel_weights when set).
  const uint16_t* pixel_labels = nullptr;  // [H, W]
  const int* label_ids = nullptr;          // [J]
  // Sparse channel groups: Gaussian i adds group_val[e] (GW values) to group group_id[e] for e in
  // [group_ptr[i], group_ptr[i + 1]); the other groups get nothing from it. Output [H, W, G * GW].
  int num_groups = 0;              // G
  int group_width = 0;             // GW
  int group_grad_width = 0;        // backward: the first GWg <= GW channels of a group carry gradient
  const int* group_ptr = nullptr;  // [N + 1]
  const int* group_id = nullptr;   // [E] in [0, G)
  const T* group_val = nullptr;    // [E, GW]
  ChannelPath channel_path = ChannelPath::kAuto;
};

template <class T>
struct RasterOutputs {
  T* rgb = nullptr;          // [H, W, 3]
  T* alpha = nullptr;        // [H, W]
  T* depth = nullptr;        // [H, W] (needed when inputs.depth != null)
  T* extra = nullptr;        // [H, W, C]
  T* final_T = nullptr;      // [H, W] saved for backward
  int32_t* last = nullptr;   // [H, W] saved for backward: tile-local index + 1 of the last accumulated Gaussian
  T* weight_sums = nullptr;  // [N, J] sum_p M_j(p) alpha_n(p) T_n(p) (when num_weights > 0)
  T* groups = nullptr;       // [H, W, G * GW] (when num_groups > 0), or [G, H, W, GW] when group_planes
  bool group_planes = false;
  // With group_planes, optional: group_live[g * tiles + t] = 1 where a Gaussian of tile t has an entry in group g
  // and its plane was written there; 0 where no Gaussian adds to it, its values are +0 and its memory is left
  // unwritten (a reader substitutes the zeros). [G, tiles]
  uint8_t* group_live = nullptr;
};

// Chosen pixels grouped by tile, for rasterize_depth_at: tile t's are pixel[start[t], start[t + 1]), each
// y * W + x inside the tile, each once (in any order). tile_pixels() builds it from a per-pixel choice.
struct TilePixels {
  std::vector<int> start;  // [tiles + 1]
  std::vector<int> pixel;  // [M]
};
// chosen [H, W] (non-zero = chosen) -> px, each tile's pixels by 8x8 quadrant (top left, top right, bottom left,
// bottom right), row-major inside one, so that a pack of 8 lies in one half of the tile's batch columns and a
// Gaussian whose mask misses that half skips it (parallel over tile rows).
void tile_pixels(int width, int height, const uint8_t* chosen, TilePixels& px);

// The most gradient channels a group may have when its gradients are computed on demand (d_group_rows).
constexpr int kMaxGroupGradWidth = 8;

// Upstream gradients (null = zero) and per-Gaussian results (overwritten).
template <class T>
struct RasterGrads {
  const T* d_rgb = nullptr;          // [H, W, 3]
  const T* d_alpha = nullptr;        // [H, W]
  const T* d_depth = nullptr;        // [H, W]
  const T* d_extra = nullptr;        // [H, W, C]
  const T* d_weight_sums = nullptr;  // [N, J]
  // d groups: channel i < GWg of group g at pixel p is d_groups[p * d_group_row + g * d_group_stride + i], or,
  // with d_group_rows instead, what d_group_rows(d_group_ctx, g, y, x0, n, out) writes to out[l * GWg + i] for
  // pixel (x0 + l, y), l < n (OutputGradsT::group_rows).
  const T* d_groups = nullptr;
  int d_group_row = 0, d_group_stride = 0;
  void (*d_group_rows)(const void* ctx, int g, int y, int x0, int n, T* out) = nullptr;
  const void* d_group_ctx = nullptr;
  bool group_grads() const { return d_groups != nullptr || d_group_rows != nullptr; }
  T* mean2d = nullptr;     // [N, 2] out
  T* conic = nullptr;      // [N, 3] out (b counted once)
  T* opacity = nullptr;    // [N] out (w.r.t. opacity after the sigmoid)
  T* color = nullptr;      // [N, 3] out
  T* depth = nullptr;      // [N] out (may be null)
  T* extra = nullptr;      // [N, C] out (may be null)
  T* group_val = nullptr;  // [E, GW] out (channels [GWg, GW) zero; may be null)
};

// Grow-only, 128-byte-aligned scratch memory viewed as an array of U. The two kernel compilations
// (raster_isa.h) each have their own pack types (simd.h), so the workspace holds bytes and each kernel names its
// own type.
class RasterScratch {
 public:
  template <class U>
  U* get(size_t count) {  // at least count U's; the contents are kept when it grows
    const size_t bytes = count * sizeof(U);
    if (blocks_.size() * sizeof(Block) < bytes) blocks_.resize((bytes + sizeof(Block) - 1) / sizeof(Block));
    return reinterpret_cast<U*>(blocks_.data());
  }

 private:
  struct alignas(128) Block {
    unsigned char b[128];
  };
  std::vector<Block> blocks_;
};

// Allocates whole cache lines (64-byte aligned): the 16-scalar records below then each fill one line (float) or two
// (double) instead of straddling two (three), as they did with operator new's 16-byte alignment. On two threads
// that made the hybrid forward 10 % and backward 7 % faster, on one nothing (docs/performance.md, session eight).
template <class T>
struct LineAllocator {
  using value_type = T;
  static constexpr std::align_val_t kAlign{64};
  LineAllocator() noexcept = default;
  template <class U>
  LineAllocator(const LineAllocator<U>&) noexcept {}
  T* allocate(size_t n) { return static_cast<T*>(::operator new(n * sizeof(T), kAlign)); }
  void deallocate(T* p, size_t) noexcept { ::operator delete(p, kAlign); }
  template <class U>
  bool operator==(const LineAllocator<U>&) const noexcept {
    return true;
  }
};
template <class T>
using LineVector = std::vector<T, LineAllocator<T>>;

// Scratch reused between calls; backward must get the workspace of the forward it differentiates (grown, never
// shrunk), and the same channel groups: per-thread tile buffers, per-pair gradients, and the tile records, which
// carry each Gaussian's group entries (first, count) from forward to backward.
template <class T>
struct RasterWorkspace {
  struct PerThread {
    RasterScratch vk;         // per-batch visit lists of a tile: Gaussian index (int) [visits]
    RasterScratch vw;         // ... and its weight (forward) or extra-channel dot (backward), packs [visits]
    RasterScratch wacc;       // forward weight-sum accumulators of the walked Gaussian, packs [J]
    RasterScratch tile_w;     // forward: the tile's Gaussians' weight sums, T [n, J] (the maps of tile_maps)
    RasterScratch tile_maps;  // forward: the pixel-weight maps each of the tile's Gaussians added to, uint32 [n]
    RasterScratch dw;         // backward d(weight_sums) of the tile's Gaussians, T [n, J]
    RasterScratch bstate;     // per-batch state, packs [batches, 7 + C + J]
    RasterScratch blast;      // per-batch active / last-contributor masks [2, batches]
    RasterScratch groups;     // the tile's channel groups: their list (int) [G], then flags (uint8) [G]
  };
  std::vector<PerThread> threads;
  LineVector<T> records;            // [N, 16] per-Gaussian records built by forward, reused by backward
  LineVector<T> tile_records;       // [P, 16] records in tile order (forward gathers, backward reuses)
  LineVector<T> chan_records;       // [N, 16] the folded walks' channel records (forward builds, backward reuses)
  int chan_n = -1;                  // the Gaussians chan_records holds (-1: the last forward did not fold)
  std::vector<uint32_t> masks;      // [P] per (tile, Gaussian) entry: bit b = listed in batch b
  std::vector<T> pair_grad;         // [P, F]
  std::vector<T> pair_w;            // [P, J] forward weight sums per pair (only the maps of pair_maps written)
  std::vector<uint32_t> pair_maps;  // [P] the pixel-weight maps each pair added to (J <= 32)
  std::vector<size_t> group_off;    // [N + 1] backward: start of each Gaussian's group-gradient pair slots
  std::vector<size_t> pair_gslot;   // [P] backward: the group-gradient slot of each pair, in tile order
  std::vector<std::array<size_t, 2>> slot_rule;  // [N] backward: each Gaussian's pair -> slot rule (group_slots)
  LineVector<uint8_t> live_rows;  // [tiles, 64 m] forward: each tile's group_live flags, a cache line per tile
  std::vector<T> pair_group;      // [sum_i pairs_i * entries_i * GWg] group gradients per pair
};

template <class T>
void rasterize_forward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws,
                       const RasterOutputs<T>& out);

template <class T>
void rasterize_backward(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws,
                        const T* final_T,     // [H, W] from forward
                        const int32_t* last,  // [H, W] from forward
                        const RasterGrads<T>& g);

// Alpha (1 - final T) and expected depth (the depth channel) at the chosen pixels only, alpha [M] and depth [M] in
// px's order: bitwise what rasterize_forward writes to out.alpha and out.depth there (rasterize_pixels.cpp), at a
// cost that grows with the chosen pixels instead of the image. in.depth is required; colours, extra channels,
// groups and pixel weights are not read.
template <class T>
void rasterize_depth_at(const RasterInputs<T>& in, const Binning& bins, RasterWorkspace<T>& ws, const TilePixels& px,
                        T* alpha, T* depth);

extern template void rasterize_forward<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                              const RasterOutputs<float>&);
extern template void rasterize_forward<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                               const RasterOutputs<double>&);
extern template void rasterize_backward<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                               const float*, const int32_t*, const RasterGrads<float>&);
extern template void rasterize_backward<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                                const double*, const int32_t*, const RasterGrads<double>&);

extern template void rasterize_depth_at<float>(const RasterInputs<float>&, const Binning&, RasterWorkspace<float>&,
                                               const TilePixels&, float*, float*);
extern template void rasterize_depth_at<double>(const RasterInputs<double>&, const Binning&, RasterWorkspace<double>&,
                                                const TilePixels&, double*, double*);

}  // namespace hgs::render
