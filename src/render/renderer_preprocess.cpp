// RendererT phase 1 and its backward: projection -> opacity sigmoid -> SH colour of the visible Gaussians (or the
// given colours) -> tile binning; backward chains projected-space gradients through SH (visible Gaussians only,
// including d mean via the view direction), the sigmoid and the projection.
#include <cmath>

#include "core/error.h"
#include "render/renderer_state.h"
#include "render/sh.h"

namespace hgs::render {

template <class T>
void RendererT<T>::preprocess(const Camera& cam, const GaussianInputsT<T>& g) {
  State& st = *st_;
  st.has_preprocess = false;
  st.has_composite = false;
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

  const int n = g.n, H = cam.height, W = cam.width;
  st.cam = make_camera<T>(cam);
  st.g = g;
  st.H = H;
  st.W = W;
  st.mean2d.resize(size_t(n) * 2);
  st.conic.resize(size_t(n) * 3);
  st.depth.resize(size_t(n));
  st.opacity.resize(size_t(n));
  st.radius.resize(size_t(n));
  st.visible = project_forward(st.cam, n, g.mean, g.log_scale, g.quat, st.mean2d.data(), st.conic.data(),
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
  st.has_preprocess = true;
}

template <class T>
void RendererT<T>::chain_preprocess(const ProjectedGradsT<T>& pg, GaussianGradsT<T>& grads) {
  State& st = *st_;
  if (!st.has_preprocess) fail("render: backward called without a successful preprocess()");
  const GaussianInputsT<T>& g = st.g;
  const size_t n = size_t(g.n);
  if (pg.mean2d.size() != 2 * n || pg.conic.size() != 3 * n || pg.depth.size() != n || pg.opacity.size() != n ||
      pg.colors.size() != 3 * n)
    fail("render: projected gradients are not sized for the {} Gaussians of preprocess()", n);
  grads.mean.resize(n * 3);
  grads.log_scale.resize(n * 3);
  grads.quat.resize(n * 4);
  grads.opacity_logit.resize(n);
#pragma omp parallel for schedule(static)
  for (int i = 0; i < g.n; ++i) {
    const T o = st.opacity[i];
    grads.opacity_logit[i] = pg.opacity[i] * o * (T(1) - o);
  }
  project_backward(st.cam, g.n, g.mean, g.log_scale, g.quat, st.radius.data(), pg.mean2d.data(), pg.conic.data(),
                   pg.depth.data(), grads.mean.data(), grads.log_scale.data(), grads.quat.data());
  if (g.colors) {
    grads.colors.assign(pg.colors.begin(), pg.colors.end());
    grads.sh.clear();
  } else {
    grads.colors.clear();
    grads.sh.resize(n * g.sh_stride * 3);
    sh_backward(g.n, g.sh_degree, g.sh_stride, g.sh, g.mean, st.cam.campos, st.radius.data(), pg.colors.data(),
                grads.sh.data(), grads.mean.data());
  }
}

template <class T>
void RendererT<T>::preprocess_backward(const ProjectedGradsT<T>& pgrads, GaussianGradsT<T>& grads) {
  chain_preprocess(pgrads, grads);
  grads.mean2d.clear();  // they live in pgrads
  grads.extra.clear();
}

template void RendererT<float>::preprocess(const Camera&, const GaussianInputsT<float>&);
template void RendererT<double>::preprocess(const Camera&, const GaussianInputsT<double>&);
template void RendererT<float>::chain_preprocess(const ProjectedGradsT<float>&, GaussianGradsT<float>&);
template void RendererT<double>::chain_preprocess(const ProjectedGradsT<double>&, GaussianGradsT<double>&);
template void RendererT<float>::preprocess_backward(const ProjectedGradsT<float>&, GaussianGradsT<float>&);
template void RendererT<double>::preprocess_backward(const ProjectedGradsT<double>&, GaussianGradsT<double>&);

}  // namespace hgs::render
