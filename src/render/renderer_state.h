// Internal: what RendererT keeps between its phases (shared by renderer.cpp, renderer_preprocess.cpp and
// renderer_composite.cpp; not part of the public API).
#pragma once
#include <cstdint>
#include <vector>

#include "render/binning.h"
#include "render/project.h"
#include "render/rasterize.h"
#include "render/renderer.h"

namespace hgs::render {

template <class T>
struct RendererT<T>::State {
  // preprocess()
  CameraT<T> cam;
  GaussianInputsT<T> g;
  bool has_preprocess = false;
  int H = 0, W = 0, visible = 0;
  std::vector<T> mean2d, conic, depth, opacity, colors;  // [N,2], [N,3], [N], [N], [N,3]
  std::vector<int> radius;                               // [N]
  const T* color_ptr = nullptr;                          // colors.data() or the given colours
  Binning bins;
  // composite()
  ChannelsT<T> ch;
  RenderSettings s;
  bool has_composite = false;
  RasterWorkspace<T> ws;
  std::vector<T> final_T;     // [H, W]
  std::vector<int32_t> last;  // [H, W]
  // backward(): projected-space gradients between its two phases
  ProjectedGradsT<T> pgrads;
};

}  // namespace hgs::render
