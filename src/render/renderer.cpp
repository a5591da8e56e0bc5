// GaussianRenderer / RendererT: buffers kept between calls, accessors, and forward() / backward() as the
// compositions of the two phases (preprocess: renderer_preprocess.cpp, composite: renderer_composite.cpp).
#include "render/renderer.h"

#include <utility>

#include "render/renderer_state.h"

namespace hgs::render {

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
  const State& st = *st_;
  ProjectedView<T> v;
  v.n = st.g.n;
  v.num_visible = st.visible;
  v.mean2d = st.mean2d.data();
  v.conic = st.conic.data();
  v.depth = st.depth.data();
  v.opacity = st.opacity.data();
  v.colors = st.color_ptr;
  v.radii = st.radius.data();
  v.campos = st.cam.campos;
  return v;
}

template <class T>
void RendererT<T>::forward(const Camera& cam, const GaussianInputsT<T>& g, const RenderSettings& s,
                           RenderOutputsT<T>& out) {
  preprocess(cam, g);
  ChannelsT<T> ch;
  ch.extra = g.extra;
  ch.num_extra = g.num_extra;
  composite(ch, s, out);
}

template <class T>
void RendererT<T>::backward(const OutputGradsT<T>& dout, GaussianGradsT<T>& grads) {
  State& st = *st_;
  composite_backward(dout, st.pgrads);
  chain_preprocess(st.pgrads, grads);
  // Swapped, not copied: both buffers stay allocated, so a warm renderer does not allocate or fill them again.
  std::swap(grads.mean2d, st.pgrads.mean2d);
  std::swap(grads.extra, st.pgrads.extra);
}

template class RendererT<float>;
template class RendererT<double>;

}  // namespace hgs::render
