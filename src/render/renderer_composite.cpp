// RendererT phase 2 and its backward: per-tile alpha compositing of RGB, alpha, depth, the extra channels and the
// pixel-weighted sums of the last preprocess(); backward gives the gradients w.r.t. the projected quantities;
// depth_at, alpha and depth at chosen pixels only.
#include "core/error.h"
#include "render/renderer_state.h"

namespace hgs::render {

namespace {

template <class T>
void set_groups(const ChannelsT<T>& ch, RasterInputs<T>& ri) {
  if (ch.num_groups <= 0 || ch.group_width <= 0) return;
  ri.num_groups = ch.num_groups;
  ri.group_width = ch.group_width;
  ri.group_ptr = ch.group_ptr;
  ri.group_id = ch.group_id;
  ri.group_val = ch.group_val;
}

// The compositing settings the rasterizer reads, the same in composite() and composite_backward(): the
// background and the pixel-weight maps (float maps or a label image with its ids).
template <class T>
void set_settings(const RenderSettings& s, RasterInputs<T>& ri) {
  for (int k = 0; k < 3; ++k) ri.background[k] = s.background[k];
  const int J = s.num_pixel_weights;
  ri.pixel_weights = J > 0 ? s.pixel_weights : nullptr;
  ri.pixel_labels = J > 0 ? s.pixel_labels : nullptr;
  ri.label_ids = J > 0 ? s.pixel_label_ids : nullptr;
  ri.num_weights = J;
}

// The projected quantities of the last preprocess() (st: RendererT's State) as the rasterizer's inputs, with the
// depth channel or without; each phase adds its channels and settings.
template <class T, class State>
RasterInputs<T> projected_inputs(const State& st, bool want_depth) {
  RasterInputs<T> ri;
  ri.width = st.W;
  ri.height = st.H;
  ri.n = st.g.n;
  ri.mean2d = st.mean2d.data();
  ri.conic = st.conic.data();
  ri.opacity = st.opacity.data();
  ri.color = st.color_ptr;
  ri.depth = want_depth ? st.depth.data() : nullptr;
  return ri;
}

}  // namespace

template <class T>
void RendererT<T>::composite(const ChannelsT<T>& ch, const RenderSettings& s, RenderOutputsT<T>& out) {
  State& st = *st_;
  st.has_composite = false;
  if (!st.has_preprocess) fail("render: composite() called without a successful preprocess()");
  const int n = st.g.n, H = st.H, W = st.W, C = ch.num_extra, J = s.num_pixel_weights;
  if (J < 0 || (J > 0 && !s.pixel_weights && !(s.pixel_labels && s.pixel_label_ids)))
    fail("render: num_pixel_weights is {} but neither pixel_weights nor pixel_labels with their ids was given", J);
  if (J > 0 && s.pixel_weights && s.pixel_labels)
    fail("render: both pixel_weights and pixel_labels were given; set one");
  for (int j = 0; j < J && s.pixel_labels; ++j)
    if (s.pixel_label_ids[j] < 0 || s.pixel_label_ids[j] > 0xFFFF)
      fail("render: pixel_label_ids[{}] is {}, not a 16-bit label", j, s.pixel_label_ids[j]);
  if (C < 0 || (C > 0 && n > 0 && !ch.extra)) fail("render: num_extra is {} but no extra array was given", C);
  const int GT = ch.num_groups * ch.group_width;
  if (ch.num_groups < 0 || ch.group_width < 0 ||
      (GT > 0 && (!ch.group_ptr || (ch.group_ptr[n] > 0 && (!ch.group_id || !ch.group_val)))))
    fail("render: {} channel groups of width {} without their entry arrays", ch.num_groups, ch.group_width);
  if (ch.group_live_tiles && !ch.group_planes) fail("render: group_live_tiles needs group_planes");
  st.ch = ch;
  st.s = s;

  const size_t P = size_t(H) * W;
  out.rgb.resize(P * 3);
  out.alpha.resize(P);
  if (s.want_depth) out.depth.resize(P);
  else out.depth.clear();
  if (C > 0) out.extra.resize(P * C);
  else out.extra.clear();
  if (J > 0) out.weight_sums.resize(size_t(n) * J);
  else out.weight_sums.clear();
  if (GT > 0) resize_discarding(out.groups, P * GT);  // the walks write or flag every value
  else out.groups.clear();
  const bool live = GT > 0 && ch.group_live_tiles;
  if (live) out.group_live.resize(size_t(ch.num_groups) * st.bins.num_tiles);
  else out.group_live.clear();
  st.final_T.resize(P);
  st.last.resize(P);
  RasterInputs<T> ri = projected_inputs<T>(st, s.want_depth);
  ri.extra = C > 0 ? ch.extra : nullptr;
  ri.num_extra = C;
  set_settings(s, ri);
  set_groups(ch, ri);
  RasterOutputs<T> ro;
  ro.groups = GT > 0 ? out.groups.data() : nullptr;
  ro.group_planes = ch.group_planes;
  ro.group_live = live ? out.group_live.data() : nullptr;
  ro.weight_sums = J > 0 ? out.weight_sums.data() : nullptr;
  ro.rgb = out.rgb.data();
  ro.alpha = out.alpha.data();
  ro.depth = s.want_depth ? out.depth.data() : nullptr;
  ro.extra = C > 0 ? out.extra.data() : nullptr;
  ro.final_T = st.final_T.data();
  ro.last = st.last.data();
  rasterize_forward(ri, st.bins, st.ws, ro);
  out.num_visible = st.visible;
  st.has_composite = true;
}

template <class T>
void RendererT<T>::depth_at(const TilePixels& px, T* alpha, T* depth) {
  State& st = *st_;
  st.has_composite = false;  // the records backward reuses are rebuilt here
  if (!st.has_preprocess) fail("render: depth_at() called without a successful preprocess()");
  const int tiles = st.bins.num_tiles;
  if (px.start.size() != size_t(tiles) + 1 || px.start.back() != int(px.pixel.size()))
    fail("render: depth_at() was given pixels for {} tiles, the image has {}", int(px.start.size()) - 1, tiles);
  rasterize_depth_at(projected_inputs<T>(st, true), st.bins, st.ws, px, alpha, depth);
}

template <class T>
void RendererT<T>::composite_backward(const OutputGradsT<T>& dout, ProjectedGradsT<T>& pg) {
  State& st = *st_;
  if (!st.has_composite) fail("render: backward called without a successful composite()");
  const int n = st.g.n, C = st.ch.num_extra;
  const bool want_depth = st.s.want_depth;
  const int Cg = dout.extra_grad_channels < 0 ? C : dout.extra_grad_channels;
  if (Cg > C) fail("render: {} extra channels carry gradient but there are only {}", Cg, C);
  pg.mean2d.resize(size_t(n) * 2);
  pg.conic.resize(size_t(n) * 3);
  pg.depth.resize(size_t(n));
  pg.opacity.resize(size_t(n));
  pg.colors.resize(size_t(n) * 3);
  if (C > 0) pg.extra.resize(size_t(n) * C);
  else pg.extra.clear();
  const int G = st.ch.num_groups, GW = st.ch.group_width;
  const bool groups = G > 0 && GW > 0;
  if (groups && (dout.group_grad_channels < 0 || dout.group_grad_channels > GW))
    fail("render: {} channels of a group carry gradient but groups have {}", dout.group_grad_channels, GW);
  if (groups && dout.group_rows && dout.group_grad_channels > kMaxGroupGradWidth)
    fail("render: group gradients computed on demand carry at most {} channels, not {}", kMaxGroupGradWidth,
         dout.group_grad_channels);
  if (groups) pg.group_val.resize(size_t(st.ch.group_ptr[n]) * GW);
  else pg.group_val.clear();

  RasterInputs<T> ri = projected_inputs<T>(st, want_depth);
  ri.extra = C > 0 ? st.ch.extra : nullptr;
  ri.num_extra = dout.extra ? Cg : 0;
  ri.extra_stride = C;
  set_settings(st.s, ri);
  set_groups(st.ch, ri);
  RasterGrads<T> rg;
  if (groups && (dout.groups || dout.group_rows) && dout.group_grad_channels > 0) {
    ri.group_grad_width = dout.group_grad_channels;
    rg.d_groups = dout.group_rows ? nullptr : dout.groups;
    rg.d_group_row = dout.group_row;
    rg.d_group_stride = dout.group_stride;
    rg.d_group_rows = dout.group_rows;
    rg.d_group_ctx = dout.group_ctx;
  }
  rg.group_val = groups ? pg.group_val.data() : nullptr;
  rg.d_weight_sums = st.s.num_pixel_weights > 0 ? dout.weight_sums : nullptr;
  rg.d_rgb = dout.rgb;
  rg.d_alpha = dout.alpha;
  rg.d_depth = want_depth ? dout.depth : nullptr;
  rg.d_extra = C > 0 ? dout.extra : nullptr;
  rg.mean2d = pg.mean2d.data();
  rg.conic = pg.conic.data();
  rg.opacity = pg.opacity.data();
  rg.color = pg.colors.data();
  rg.depth = pg.depth.data();
  rg.extra = C > 0 ? pg.extra.data() : nullptr;
  rasterize_backward(ri, st.bins, st.ws, st.final_T.data(), st.last.data(), rg);
}

template void RendererT<float>::composite(const ChannelsT<float>&, const RenderSettings&, RenderOutputsT<float>&);
template void RendererT<double>::composite(const ChannelsT<double>&, const RenderSettings&, RenderOutputsT<double>&);
template void RendererT<float>::depth_at(const TilePixels&, float*, float*);
template void RendererT<double>::depth_at(const TilePixels&, double*, double*);
template void RendererT<float>::composite_backward(const OutputGradsT<float>&, ProjectedGradsT<float>&);
template void RendererT<double>::composite_backward(const OutputGradsT<double>&, ProjectedGradsT<double>&);

}  // namespace hgs::render
