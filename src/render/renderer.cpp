// GaussianRenderer / RendererT: ties projection -> opacity sigmoid -> SH colour -> binning -> rasterize together,
// keeps every buffer in State between calls, and chains the stage backwards in reverse order.
#include "render/renderer.h"

#include <cmath>

#include "core/error.h"
#include "render/binning.h"
#include "render/project.h"
#include "render/rasterize.h"
#include "render/sh.h"

namespace hgs::render {

template <class T>
struct RendererT<T>::State {
  CameraT<T> cam;
  GaussianInputsT<T> g;
  RenderSettings s;
  bool has_forward = false;
  int H = 0, W = 0;
  std::vector<T> mean2d, conic, depth, opacity, colors;  // [N,2], [N,3], [N], [N], [N,3]
  std::vector<int> radius;                              // [N]
  const T* color_ptr = nullptr;
  Binning bins;
  RasterWorkspace<T> ws;
  std::vector<T> final_T;      // [H, W]
  std::vector<int32_t> last;   // [H, W]
  std::vector<T> g_conic, g_opacity, g_color, g_depth;  // backward scratch
};

template <class T>
RendererT<T>::RendererT() : st_(new State) {}
template <class T>
RendererT<T>::~RendererT() {
  delete st_;
}

template <class T>
void RendererT<T>::release() {
  State* fresh = new State;
  delete st_;
  st_ = fresh;
}

template <class T>
const std::vector<int>& RendererT<T>::radii() const {
  return st_->radius;
}

template <class T>
ProjectedView<T> RendererT<T>::projected() const {
  ProjectedView<T> v;
  v.n = st_->g.n;
  v.mean2d = st_->mean2d.data();
  v.conic = st_->conic.data();
  v.depth = st_->depth.data();
  v.opacity = st_->opacity.data();
  v.colors = st_->color_ptr;
  v.radii = st_->radius.data();
  return v;
}

template <class T>
void RendererT<T>::forward(const Camera& cam, const GaussianInputsT<T>& g, const RenderSettings& s,
                           RenderOutputsT<T>& out) {
  State& st = *st_;
  st.has_forward = false;
  if (cam.width <= 0 || cam.height <= 0 || !(cam.fx > 0) || !(cam.fy > 0))
    fail("render: invalid camera ({}x{} px, fx={}, fy={})", cam.width, cam.height, cam.fx, cam.fy);
  if (g.n < 0) fail("render: negative Gaussian count {}", g.n);
  if (g.n > 0 && (!g.mean || !g.log_scale || !g.quat || !g.opacity_logit))
    fail("render: mean, log_scale, quat and opacity_logit arrays are required");
  if (!g.colors) {
    if (g.n > 0 && !g.sh) fail("render: neither SH coefficients nor precomputed colours were given");
    if (g.sh_degree < 0 || g.sh_degree > 3) fail("render: SH degree {} is outside 0..3", g.sh_degree);
    if (g.sh_stride < sh_num_coeffs(g.sh_degree))
      fail("render: sh_stride {} is smaller than the {} coefficients of degree {}", g.sh_stride,
           sh_num_coeffs(g.sh_degree), g.sh_degree);
  }
  if (s.num_pixel_weights < 0 || (s.num_pixel_weights > 0 && !s.pixel_weights))
    fail("render: num_pixel_weights is {} but no pixel_weights array was given", s.num_pixel_weights);
  if (g.num_extra < 0 || (g.num_extra > 0 && g.n > 0 && !g.extra))
    fail("render: num_extra is {} but no extra array was given", g.num_extra);

  const int n = g.n, H = cam.height, W = cam.width, C = g.num_extra;
  st.cam = make_camera<T>(cam);
  st.g = g;
  st.s = s;
  st.H = H;
  st.W = W;
  st.mean2d.resize(size_t(n) * 2);
  st.conic.resize(size_t(n) * 3);
  st.depth.resize(size_t(n));
  st.opacity.resize(size_t(n));
  st.radius.resize(size_t(n));
  const int visible = project_forward(st.cam, n, g.mean, g.log_scale, g.quat, st.mean2d.data(), st.conic.data(),
                                      st.depth.data(), st.radius.data());
#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) st.opacity[i] = T(1) / (T(1) + std::exp(-g.opacity_logit[i]));
  if (g.colors) {
    st.color_ptr = g.colors;
  } else {
    st.colors.resize(size_t(n) * 3);
    sh_forward(n, g.sh_degree, g.sh_stride, g.sh, g.mean, st.cam.campos, st.radius.data(), st.colors.data());
    st.color_ptr = st.colors.data();
  }
  bin_gaussians(W, H, n, st.mean2d.data(), st.conic.data(), st.opacity.data(), st.depth.data(), st.radius.data(),
                st.bins);

  const size_t P = size_t(H) * W;
  out.rgb.resize(P * 3);
  out.alpha.resize(P);
  if (s.want_depth) out.depth.resize(P);
  else out.depth.clear();
  if (C > 0) out.extra.resize(P * C);
  else out.extra.clear();
  const int J = s.num_pixel_weights;
  if (J > 0) out.weight_sums.resize(size_t(n) * J);
  else out.weight_sums.clear();
  st.final_T.resize(P);
  st.last.resize(P);
  RasterInputs<T> ri;
  ri.width = W;
  ri.height = H;
  ri.n = n;
  ri.mean2d = st.mean2d.data();
  ri.conic = st.conic.data();
  ri.opacity = st.opacity.data();
  ri.color = st.color_ptr;
  ri.depth = s.want_depth ? st.depth.data() : nullptr;
  ri.extra = C > 0 ? g.extra : nullptr;
  ri.num_extra = C;
  for (int k = 0; k < 3; ++k) ri.background[k] = s.background[k];
  ri.pixel_weights = J > 0 ? s.pixel_weights : nullptr;
  ri.num_weights = J;
  RasterOutputs<T> ro;
  ro.weight_sums = J > 0 ? out.weight_sums.data() : nullptr;
  ro.rgb = out.rgb.data();
  ro.alpha = out.alpha.data();
  ro.depth = s.want_depth ? out.depth.data() : nullptr;
  ro.extra = C > 0 ? out.extra.data() : nullptr;
  ro.final_T = st.final_T.data();
  ro.last = st.last.data();
  rasterize_forward(ri, st.bins, st.ws, ro);
  out.num_visible = visible;
  st.has_forward = true;
}

template <class T>
void RendererT<T>::backward(const OutputGradsT<T>& dout, GaussianGradsT<T>& grads) {
  State& st = *st_;
  if (!st.has_forward) fail("render: backward() called without a successful forward()");
  const GaussianInputsT<T>& g = st.g;
  const int n = g.n, C = g.num_extra;
  const bool want_depth = st.s.want_depth;
  grads.mean.resize(size_t(n) * 3);
  grads.log_scale.resize(size_t(n) * 3);
  grads.quat.resize(size_t(n) * 4);
  grads.opacity_logit.resize(size_t(n));
  grads.mean2d.resize(size_t(n) * 2);
  if (C > 0) grads.extra.resize(size_t(n) * C);
  else grads.extra.clear();
  st.g_conic.resize(size_t(n) * 3);
  st.g_opacity.resize(size_t(n));
  st.g_depth.resize(size_t(n));
  T* gcolor;
  if (g.colors) {
    grads.colors.resize(size_t(n) * 3);
    // SH given too (a caller that made the colours from SH itself): zeros it can accumulate into
    if (g.sh) grads.sh.assign(size_t(n) * g.sh_stride * 3, T(0));
    else grads.sh.clear();
    gcolor = grads.colors.data();
  } else {
    grads.colors.clear();
    st.g_color.resize(size_t(n) * 3);
    gcolor = st.g_color.data();
  }

  RasterInputs<T> ri;
  ri.width = st.W;
  ri.height = st.H;
  ri.n = n;
  ri.mean2d = st.mean2d.data();
  ri.conic = st.conic.data();
  ri.opacity = st.opacity.data();
  ri.color = st.color_ptr;
  ri.depth = want_depth ? st.depth.data() : nullptr;
  const int Cg = dout.extra_grad_channels < 0 ? C : dout.extra_grad_channels;
  if (Cg > C) fail("render: {} extra channels carry gradient but there are only {}", Cg, C);
  ri.extra = C > 0 ? g.extra : nullptr;
  ri.num_extra = dout.extra ? Cg : 0;
  ri.extra_stride = C;
  for (int k = 0; k < 3; ++k) ri.background[k] = st.s.background[k];
  ri.pixel_weights = st.s.num_pixel_weights > 0 ? st.s.pixel_weights : nullptr;
  ri.num_weights = st.s.num_pixel_weights;
  RasterGrads<T> rg;
  rg.d_weight_sums = st.s.num_pixel_weights > 0 ? dout.weight_sums : nullptr;
  rg.d_rgb = dout.rgb;
  rg.d_alpha = dout.alpha;
  rg.d_depth = want_depth ? dout.depth : nullptr;
  rg.d_extra = C > 0 ? dout.extra : nullptr;
  rg.mean2d = grads.mean2d.data();
  rg.conic = st.g_conic.data();
  rg.opacity = st.g_opacity.data();
  rg.color = gcolor;
  rg.depth = st.g_depth.data();
  rg.extra = C > 0 ? grads.extra.data() : nullptr;
  rasterize_backward(ri, st.bins, st.ws, st.final_T.data(), st.last.data(), rg);

#pragma omp parallel for schedule(static)
  for (int i = 0; i < n; ++i) {
    const T o = st.opacity[i];
    grads.opacity_logit[i] = st.g_opacity[i] * o * (T(1) - o);
  }
  project_backward(st.cam, n, g.mean, g.log_scale, g.quat, st.radius.data(), grads.mean2d.data(), st.g_conic.data(),
                   st.g_depth.data(), grads.mean.data(), grads.log_scale.data(), grads.quat.data());
  if (!g.colors) {
    grads.sh.resize(size_t(n) * g.sh_stride * 3);
    sh_backward(n, g.sh_degree, g.sh_stride, g.sh, g.mean, st.cam.campos, st.radius.data(), gcolor, grads.sh.data(),
                grads.mean.data());
  }
}

template class RendererT<float>;
template class RendererT<double>;

}  // namespace hgs::render
