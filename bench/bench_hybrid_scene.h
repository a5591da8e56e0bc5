// The hybrid benchmark scene shared by bench_hybrid and bench_scale: the Gaussian box of bench_scene.h seen by
// two cameras 0.2 apart at W x H (fx = fy = 300 W / 320, so the field of view does not change with the size);
// K = 8 objects laid out as a 4 x 2 grid of mask cells inside a border of W / 20 pixels, D = 512 random unit
// reference features per object. The training images are renders of the model; the model handed to training
// has its DC colours perturbed by N(0, 0.3), so gradients are real. The scene's data has no SCL classes, so the
// hybrid step on it runs the object terms only (eqs. 6 and 14, association, fusion); with_scl() gives the same
// data with every view's SCL classes set as load_hybrid_data sets them, so that the step also runs the paper's
// language term (eqs. 9-10: the pixel-weight channels, the pooled predictions and f's row updates, D = 512): the
// full method, the one the paper times. The box's state is easier than a capture's: most Gaussians are hidden and
// keep a one-hot association, the clean grid masks give each Gaussian one object entry, and the observation table
// has 2 views, so q-weighted work (f's row updates, the object groups, the fusion) is a fraction of what `hgs
// train` does on a capture (docs/performance.md, session twelve; bench/train_steps.sh times that).
#pragma once
#include <random>
#include <string>
#include <vector>

#include "bench_scene.h"
#include "hybrid/data.h"
#include "hybrid/scl.h"
#include "model/render_inputs.h"
#include "render/renderer.h"
#include "train/train_views.h"

namespace hgs::bench {

constexpr int kK = 8, kD = 512, kViews = 2;

inline LabelMap grid_labels(int W, int H) {
  LabelMap lab(W, H, 0);
  const int b = W / 20;
  for (int y = b; y < H - b; ++y)
    for (int x = b; x < W - b; ++x)
      lab.at(x, y) = uint16_t(1 + (x - b) * 4 / (W - 2 * b) + 4 * ((y - b) * 2 / (H - 2 * b)));
  return lab;
}

struct HybridScene {
  GaussianModel model;
  std::vector<train::TrainView> views;
  hybrid::HybridData data;
  // n Gaussians (scales times `scale`) rendered at W x H.
  explicit HybridScene(int W = kW, int H = kH, int n = kN, float scale = 1.f) {
    GaussianModel gt = bench_model(1234, n, scale);
    render::GaussianRenderer r;
    render::RenderOutputs out;
    render::GaussianInputs in = render_inputs(gt);
    std::mt19937 rng(7);
    std::normal_distribution<float> N(0, 1);
    data.num_labels = kK + 1;
    data.dim = kD;
    for (int v = 0; v < kViews; ++v) {
      train::TrainView tv;
      tv.name = "bench" + std::to_string(v);
      tv.cam = bench_camera(0.2f * v, W, H);
      r.forward(tv.cam, in, {}, out);
      tv.image = Image(W, H, 3);
      tv.image.px = out.rgb;
      views.push_back(tv);
      hybrid::MaskView mv;
      mv.width = W;
      mv.height = H;
      mv.fx = mv.fy = tv.cam.fx;
      mv.cx = tv.cam.cx;
      mv.cy = tv.cam.cy;
      mv.t[0] = 0.2 * v;
      mv.labels = grid_labels(W, H);
      data.masks.push_back(mv);
      hybrid::HybridView hv;
      hv.area.assign(kK + 1, 0.f);
      for (uint16_t l : mv.labels.v) hv.area[l] += 1;
      hv.zref.assign(size_t(kK + 1) * kD, 0.f);
      for (int l = 0; l <= kK; ++l) {
        hv.present.push_back(l);
        if (l > 0) hv.fg.push_back(l);
        for (int d = 0; d < kD; ++d) hv.zref[size_t(l) * kD + d] = N(rng);
        hybrid::normalize(&hv.zref[size_t(l) * kD], kD);
      }
      data.views.push_back(hv);
    }
    model = gt;
    std::normal_distribution<float> P(0, 0.3f);
    for (int i = 0; i < n; ++i)
      for (int c = 0; c < 3; ++c) model.sh[size_t(i) * 48 + c] += P(rng);
  }
};

// The data with each view's SCL classes set from its foreground labels and background area as
// load_hybrid_data does (config.h's scl_background and min_mask_pixels): the full method's language term runs.
inline hybrid::HybridData with_scl(hybrid::HybridData d, const hybrid::HybridConfig& cfg = {}) {
  for (hybrid::HybridView& hv : d.views)
    hv.scl = hybrid::scl_classes(hv.fg, hv.area[0], cfg.scl_background, cfg.min_mask_pixels);
  return d;
}

}  // namespace hgs::bench
