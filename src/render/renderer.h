// Differentiable CPU Gaussian splatting: the public, trainer-independent API of the render module.
//
// Pipeline (each stage has its own file with forward and backward on plain arrays, templated on the scalar so
// the tests run the same code in double; float is the production path):
//   project.{h,cpp}   EWA projection of 3D Gaussians to 2D conics (+0.3 px low-pass), depth, radius; the math
//                     written once for one Gaussian or a pack of 8 (project_pack.h: float runs 8 per vector)
//   sh.{h,cpp}        spherical-harmonics colour per view direction (degree 0..3), clamped at 0 as in 3DGS
//   binning.{h,cpp}   16x16 tile binning, per-tile front-to-back depth order
//   rasterize.h, rasterize_{forward,backward}.cpp (shared: rasterize_common.h, rasterize_masks.h)
//                     per-pixel front-to-back alpha compositing of RGB, alpha, depth and C extra channels
//   rasterize_pixels.cpp, tile_pixels.cpp
//                     the forward's alpha and depth at chosen pixels only (depth_at; the occlusion test)
//   raster_isa.{h,cpp} the AVX2 or the AVX-512 compilation of the rasterizer kernels, chosen at run time
//   simd.h            8-lane packs (GCC vector extensions) and the fast exp used by the rasterizer
// GaussianRenderer (= RendererT<float>) ties them together in two phases and keeps every buffer between calls
// (renderer_state.h); renderer_preprocess.cpp and renderer_composite.cpp hold the phases, renderer.cpp the rest.
//
// Data flow (arrays are [N, ...] per Gaussian unless noted; everything kept in State):
// preprocess(cam, inputs):
//   mean, log_scale, quat --project_forward--> mean2d [N,2], conic [N,3], depth [N], radius [N] (0 = culled)
//   opacity_logit --sigmoid--> opacity [N]
//   sh --sh_forward(view dir from the camera centre), visible Gaussians only--> colors [N,3] (0 when culled);
//       or the given colors as they are
//   mean2d, conic, opacity, depth, radius --bin_gaussians--> per-tile lists sorted by (depth, index),
//       Gaussian-major pair numbering, opacity-aware boxes
//   after preprocess, projected() shows mean2d, conic, depth, opacity, colors, radii and the camera centre; a
//   caller may build extra channels from them (e.g. q_k * colour) before compositing.
// composite(channels, settings, out):
//   --rasterize_forward--> rgb [H,W,3], alpha [H,W], depth [H,W], extra [H,W,C], weight_sums [N,J];
//       saved: final T [H,W], last contributor [H,W], per-Gaussian records, batch masks
// The backward runs the same chain in reverse, in two matching phases:
// composite_backward(dout, pgrads):
//   d rgb/alpha/depth/extra/weight_sums --rasterize_backward--> per (tile, Gaussian) pair slots, reduced per
//       Gaussian in fixed order: ProjectedGrads d mean2d [N,2] (the densification statistic), d conic,
//       d opacity, d colors, d depth, d extra
//   (between the two phases the caller may add to pgrads.colors, e.g. the colour gradient of the extra channels
//   it built)
// preprocess_backward(pgrads, grads):
//   d opacity --sigmoid'--> d opacity_logit;  d colors --sh_backward, visible only--> d sh (+ d mean via the view
//       direction), or d colors as they are when colours were given
//   d mean2d, d conic, d depth --project_backward--> d mean, d log_scale, d quat
// forward() = preprocess + composite of inputs.extra; backward() = composite_backward + preprocess_backward
// (with mean2d and extra moved into GaussianGrads).
// Results are bitwise deterministic for given inputs, independent of the OpenMP thread count.
// Note for densification: 3DGS thresholds the NDC-space gradient (2e-4); d/d(ndc) = d/d(pixel) * (W/2, H/2).
//
// Conventions
// - Camera: world-to-camera rotation R (row-major 3x3) and translation t (x_cam = R x_world + t); pinhole
//   intrinsics in COLMAP's pixel convention (origin at the top-left corner of the top-left pixel), so pixel
//   (x, y) is evaluated at (x + 0.5, y + 0.5).
// - Gaussians: mean [N,3]; log_scale [N,3] (scale = exp); quat [N,4] as (w, x, y, z), normalised inside (the
//   gradient goes through the normalisation); opacity_logit [N] (opacity = sigmoid); sh [N, S, 3] with
//   S = sh_stride >= (sh_degree + 1)^2 coefficients, coefficient-major then RGB (the 3DGS feature layout);
//   colour = max(SH(dir) + 0.5, 0) with dir = normalise(mean - camera centre).
// - Optional `colors` [N,3] replace the SH colour (used by object-conditioned rendering); colour is then used as
//   given (no clamp, also for culled Gaussians), and its gradient is returned in GaussianGrads::colors
//   (GaussianGrads::sh then stays empty, even if `sh` was passed too).
// - Extra channels: extra [N, C] per-Gaussian vectors, composited as sum_n v_n alpha_n T_n (no background).
// - Outputs: rgb [H,W,3] = sum c alpha T + T_final * background; alpha [H,W] = 1 - T_final;
//   depth [H,W] = sum z_n alpha_n T_n (expected depth, not divided by alpha); extra [H,W,C].
// - 3DGS cut-offs: skip a Gaussian at a pixel when alpha < 1/255; alpha clamped to 0.99 (no gradient through
//   the clamp); stop when the transmittance would drop below 1e-4 (T * (1 - alpha) < 1e-4 is tested before
//   accumulating, so that Gaussian is not composited). A Gaussian only reaches the tiles its 3-sigma square
//   touches (3DGS truncation); binning additionally drops tiles where alpha < 1/255 everywhere (same image).
// - Projection: the Jacobian uses x/z, y/z clamped to 1.3 tan(half FOV) (3DGS); the gradient is the exact one of
//   that function (zero w.r.t. x, y when clamped; 3DGS's own backward has a 2x factor on the z term there).
#pragma once
#include <cstdint>
#include <vector>

#include "core/scratch_vector.h"

namespace hgs::render {

// Camera-space depth below which a Gaussian is culled, unless a model says otherwise (TrainConfig::near_plane;
// gsplat's default; 3DGS's rasterizer culls at 0.2 scene units).
inline constexpr float kDefaultNearPlane = 0.01f;

struct Camera {
  int width = 0, height = 0;
  float fx = 0, fy = 0, cx = 0, cy = 0;
  float R[9] = {1, 0, 0, 0, 1, 0, 0, 0, 1};  // world -> camera, row-major
  float t[3] = {0, 0, 0};
  float near_plane = kDefaultNearPlane;  // Gaussians with camera-space depth below this are culled
};

// Read-only views of the Gaussian parameters (plain arrays, not owned). T = float in production; the pipeline is
// also instantiated for double so tests can check gradients exactly.
template <class T>
struct GaussianInputsT {
  int n = 0;
  const T* mean = nullptr;           // [N, 3]
  const T* log_scale = nullptr;      // [N, 3]
  const T* quat = nullptr;           // [N, 4] (w, x, y, z)
  const T* opacity_logit = nullptr;  // [N]
  const T* sh = nullptr;             // [N, sh_stride, 3]; may be null when `colors` is given
  int sh_stride = 1;
  int sh_degree = 0;          // active degree, 0..3
  const T* colors = nullptr;  // [N, 3] optional precomputed colours (replace SH)
  const T* extra = nullptr;   // [N, num_extra] optional; forward() only (passed on to composite())
  int num_extra = 0;
};
using GaussianInputs = GaussianInputsT<float>;

// Per-Gaussian vectors composite() blends besides RGB, alpha and depth. They are given after preprocess(), so a
// caller can build them from projected() (e.g. q_k * colour for the hybrid method's object channels).
template <class T>
struct ChannelsT {
  const T* extra = nullptr;  // [N, num_extra]
  int num_extra = 0;         // C
  // Sparse channel groups (rasterize.h): Gaussian i adds group_val[e] to group group_id[e] for e in
  // [group_ptr[i], group_ptr[i + 1]) and nothing to the other groups; composited into RenderOutputs::groups
  // [H, W, G * GW] at a cost per Gaussian visit of its own entries.
  int num_groups = 0;              // G
  int group_width = 0;             // GW
  const int* group_ptr = nullptr;  // [N + 1]
  const int* group_id = nullptr;   // [E] in [0, G)
  const T* group_val = nullptr;    // [E, GW]
  // RenderOutputs::groups as planes [G, H, W, GW] instead of [H, W, G * GW]: a reader of one group's pixels (the
  // object losses' crops, object_losses.h) then reads contiguous memory, with no copy of its own.
  bool group_planes = false;
  // With group_planes: write a group's plane only in the tiles where some Gaussian has an entry in the group, and
  // flag them in RenderOutputs::group_live. Elsewhere the plane's values are +0 (nothing adds to them) but its
  // memory is not written: a reader that honours the flags is spared writing and reading the zeros (the hybrid
  // method's objects each cover a part of the image).
  bool group_live_tiles = false;
};
using Channels = ChannelsT<float>;

// Compositing settings (used by composite(); preprocess() needs none).
struct RenderSettings {
  float background[3] = {0, 0, 0};
  bool want_depth = true;
  // Optional per-pixel weight maps M_j [J, H, W] (planar: map j's rows, one after another; a batch of pixels is
  // one load per map): composite then also returns per-Gaussian sums
  // weight_sums[n, j] = sum_p M_j(p) alpha_n(p) T_n(p), differentiable through OutputGrads::weight_sums.
  const float* pixel_weights = nullptr;
  int num_pixel_weights = 0;  // J
  // Hard maps as one label image instead: M_j(p) = 1 where pixel_labels[p] == pixel_label_ids[j], else 0 (the
  // same sums as the float maps of those values, without J floats per pixel). Set these or pixel_weights.
  const uint16_t* pixel_labels = nullptr;  // [H, W]
  const int* pixel_label_ids = nullptr;    // [J], each >= 0
};

template <class T>
struct RenderOutputsT {
  std::vector<T> rgb;          // [H, W, 3]
  std::vector<T> alpha;        // [H, W]
  std::vector<T> depth;        // [H, W] (empty when !want_depth)
  std::vector<T> extra;        // [H, W, C] (empty when C = 0)
  std::vector<T> weight_sums;  // [N, J] when pixel weights were given (else empty)
  // [H, W, G * GW] (or [G, H, W, GW]: group_planes) when channel groups were given. Its growth is not zeroed
  // (ScratchVector): the walks write every value, or flag the tiles they leave (group_live); zeroing a view's new
  // planes took 7 ms a step on one thread at 1000x700 with J = 16-24.
  ScratchVector<T> groups;
  // [G, tiles_y, tiles_x] of kTileSize-pixel tiles, with group_live_tiles (else empty): 1 where group g's plane was
  // written, 0 where its values are +0 and groups holds whatever was there before.
  std::vector<uint8_t> group_live;
  int num_visible = 0;  // Gaussians that passed culling
};
using RenderOutputs = RenderOutputsT<float>;

// Upstream gradients of a scalar loss with respect to the outputs. Null pointers mean zero.
template <class T>
struct OutputGradsT {
  const T* rgb = nullptr;          // [H, W, 3]
  const T* alpha = nullptr;        // [H, W]
  const T* depth = nullptr;        // [H, W]
  const T* extra = nullptr;        // [H, W, C]
  const T* weight_sums = nullptr;  // [N, J]
  // Only channels [0, extra_grad_channels) of `extra` carry gradient; the others are forward-only (e.g. an
  // opacity render used as a constant) and backward skips them (their input gradient is 0). -1 = all.
  int extra_grad_channels = -1;
  // Channel groups: the first group_grad_channels of each group carry gradient, read from
  // groups[p * group_row + g * group_stride + i] (so they may live inside another layout).
  const T* groups = nullptr;
  int group_row = 0, group_stride = 0, group_grad_channels = 0;
  // Or, instead of `groups`, computed on demand: group_rows(group_ctx, g, y, x0, n, out) writes the
  // group_grad_channels gradient channels of group g at pixels (x0 .. x0 + n - 1, y) to out [n,
  // group_grad_channels]. Backward asks only for the groups a tile's Gaussians have entries in, eight pixels at a
  // time, from several threads at once; no [H, W, G * ...] buffer is needed (the hybrid method's object
  // gradients: hybrid/object_losses.h).
  void (*group_rows)(const void* ctx, int g, int y, int x0, int n, T* out) = nullptr;
  const void* group_ctx = nullptr;
};
using OutputGrads = OutputGradsT<float>;

// Gradients with respect to the projected quantities of projected(): what composite_backward() returns and
// preprocess_backward() takes. composite_backward() resizes and overwrites every buffer; the caller may add to
// them in between (e.g. to `colors` the colour gradient of extra channels it built from projected().colors).
template <class T>
struct ProjectedGradsT {
  std::vector<T> mean2d;     // [N, 2] dL/d(projected centre) in pixels (densification statistic)
  std::vector<T> conic;      // [N, 3] (b counted once)
  std::vector<T> depth;      // [N] camera-space depth (zeros when the depth channel was off)
  std::vector<T> opacity;    // [N] w.r.t. the opacity after the sigmoid
  std::vector<T> colors;     // [N, 3] w.r.t. projected().colors
  std::vector<T> extra;      // [N, C] w.r.t. the composited channels (0 for forward-only ones)
  std::vector<T> group_val;  // [E, GW] w.r.t. the channel groups' values (0 for forward-only channels)
};
using ProjectedGrads = ProjectedGradsT<float>;

// Gradients with respect to the inputs. Buffers are resized and overwritten (not accumulated).
template <class T>
struct GaussianGradsT {
  std::vector<T> mean;           // [N, 3]
  std::vector<T> log_scale;      // [N, 3]
  std::vector<T> quat;           // [N, 4]
  std::vector<T> opacity_logit;  // [N]
  std::vector<T> sh;             // [N, sh_stride, 3] (zero beyond the active degree and for culled Gaussians);
                                 // empty when colours were given
  std::vector<T> colors;         // [N, 3] when precomputed colours were given (else empty)
  // Filled by backward() only (moved from its ProjectedGrads); preprocess_backward() leaves them empty.
  std::vector<T> extra;   // [N, C]
  std::vector<T> mean2d;  // [N, 2] dL/d(projected centre) in pixels (densification statistic)
};
using GaussianGrads = GaussianGradsT<float>;

// What the last preprocess() computed per Gaussian (views into the renderer's buffers, valid until the next
// preprocess() or release()).
template <class T>
struct ProjectedView {
  int n = 0;
  int num_visible = 0;         // Gaussians with radius > 0
  const T* mean2d = nullptr;   // [N, 2] projected centre, pixels
  const T* conic = nullptr;    // [N, 3] inverse 2D covariance (a, b, c)
  const T* depth = nullptr;    // [N] camera-space depth
  const T* opacity = nullptr;  // [N] sigmoid(opacity_logit)
  const T* colors = nullptr;   // [N, 3] colours composited (SH result, 0 when culled; or the given colours)
  const int* radii = nullptr;  // [N] 0 = culled
  const T* campos = nullptr;   // [3] camera centre in world space (-R^T t), origin of the SH view directions
};

struct TilePixels;  // rasterize.h

// The whole pipeline for scalar T (float and double are instantiated in renderer*.cpp).
template <class T>
class RendererT {
 public:
  RendererT();
  ~RendererT();
  RendererT(const RendererT&) = delete;
  RendererT& operator=(const RendererT&) = delete;

  // Phase 1: projection, opacity sigmoid, colours (SH for the visible Gaussians, or the given colours) and tile
  // binning; results in projected(). The input arrays must stay alive and unchanged until preprocess_backward().
  // g.extra / g.num_extra are not read. Bad input (camera, degrees, missing arrays) throws hgs::Error.
  void preprocess(const Camera& cam, const GaussianInputsT<T>& g);
  // Phase 2: composites RGB, alpha, depth, the extra channels and the pixel-weighted sums of the last
  // preprocess(). ch.extra and s.pixel_weights (or s.pixel_labels and their ids) must stay alive and unchanged
  // until composite_backward(). May be called again (other channels or settings) after one preprocess(); backward
  // differentiates the last call.
  void composite(const ChannelsT<T>& ch, const RenderSettings& s, RenderOutputsT<T>& out);
  // Alpha and expected depth at chosen pixels only, from the last preprocess(): bitwise RenderOutputs::alpha and
  // ::depth of composite() with want_depth at those pixels, at a cost that grows with the pixels chosen instead of
  // the image (the occlusion test reads the surface depth at the Gaussians' centres only). px: tile_pixels() of
  // this camera's image (rasterize.h); alpha [M], depth [M] in px's order. Not differentiable: a later
  // composite_backward() needs a composite() first.
  void depth_at(const TilePixels& px, T* alpha, T* depth);
  // Gradients of the last composite() w.r.t. the projected quantities, for the given output gradients.
  void composite_backward(const OutputGradsT<T>& dout, ProjectedGradsT<T>& pgrads);
  // Chains projected-space gradients (from composite_backward(), possibly added to) through SH, the sigmoid and
  // the projection of the last preprocess(). Fills mean, log_scale, quat, opacity_logit and sh (or colors).
  void preprocess_backward(const ProjectedGradsT<T>& pgrads, GaussianGradsT<T>& grads);

  // Both phases in one call: preprocess(cam, g), then composite({g.extra, g.num_extra}, s, out).
  void forward(const Camera& cam, const GaussianInputsT<T>& g, const RenderSettings& s, RenderOutputsT<T>& out);
  // composite_backward + preprocess_backward; also fills grads.mean2d and grads.extra.
  void backward(const OutputGradsT<T>& dout, GaussianGradsT<T>& grads);

  // Frees every buffer (the next call must be preprocess() or forward()).
  void release();

  // Per-Gaussian visibility of the last preprocess: radius in pixels (0 = culled). [N]
  const std::vector<int>& radii() const;
  // Per-Gaussian intermediate results of the last preprocess.
  ProjectedView<T> projected() const;

 private:
  struct State;  // renderer_state.h
  // preprocess_backward() without touching grads.mean2d / grads.extra (backward() swaps its own in).
  void chain_preprocess(const ProjectedGradsT<T>& pgrads, GaussianGradsT<T>& grads);
  State* st_;
};

extern template class RendererT<float>;
extern template class RendererT<double>;

class GaussianRenderer : public RendererT<float> {
 public:
  using RendererT<float>::RendererT;
};

}  // namespace hgs::render
