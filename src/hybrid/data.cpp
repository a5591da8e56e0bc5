#include "hybrid/data.h"

#include <algorithm>

#include "core/error.h"
#include "core/npy.h"
#include "core/parallel.h"
#include "hybrid/assign.h"

namespace hgs::hybrid {

std::vector<int> scl_classes(const std::vector<int>& fg, float background_area, const std::string& rule,
                             int min_pixels) {
  const bool add = rule == "on" || (rule == "auto" && fg.size() < 2);
  std::vector<int> out;
  if (add && background_area >= min_pixels) out.push_back(0);
  out.insert(out.end(), fg.begin(), fg.end());
  return out;
}

MaskView mask_view_geometry(const View& v) {
  MaskView mv;
  mv.width = v.width;
  mv.height = v.height;
  mv.fx = v.fx;
  mv.fy = v.fy;
  mv.cx = v.cx;
  mv.cy = v.cy;
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) mv.R[3 * r + c] = v.R(r, c);
    mv.t[r] = v.t[r];
  }
  return mv;
}

HybridData load_hybrid_data(const Scene& scene, const std::vector<int>& idx, const HybridConfig& cfg, bool progress) {
  HybridData d;
  const int K = scene.num_objects();
  if (K == 0)
    fail(
        "{}: the hybrid method needs object masks (masks/<stem>.png) but none were found: add them with `hgs prepare "
        "PHOTOS --out SCENE --sam SAM.safetensors` (a rerun keeps the poses) or `hgs masks generate`, or train "
        "without objects with --method rgb",
        scene.root.string());
  d.num_labels = K + 1;
  d.masks.resize(idx.size());
  d.views.resize(idx.size());
  for (int i : idx) {
    const View& v = scene.views[i];
    if (!v.mask_path) fail("{}: view '{}' has no mask (masks/{}.png)", scene.root.string(), v.name, v.stem);
    if (!v.feature_path)
      fail(
          "{}: view '{}' has no language features (features/{}.npy); run `hgs features` or `hgs prepare` with --clip "
          "first, or train with --method rgb",
          scene.root.string(), v.name, v.stem);
  }
  d.dim = static_cast<int>(read_npy_header(*scene.views[idx[0]].feature_path).shape.back());
  parallel_for_progress("load masks+features", long(idx.size()), progress, [&](long j) {
    const View& v = scene.views[idx[j]];
    MaskView& mv = d.masks[j];
    mv = mask_view_geometry(v);
    mv.labels = *scene.load_mask(idx[j]);
    const std::vector<uint8_t> gaps_unobserved = gap_pixels(mv.labels, cfg.gaps);  // empty: gaps are background
    if (auto conf = scene.load_confidence(idx[j])) {
      apply_confidence(mv.labels, *conf, cfg.tau1);
      if (cfg.unconfident_unobserved) mv.observed = confident_pixels(*conf, cfg.tau1);
    }
    if (!gaps_unobserved.empty()) {
      if (mv.observed.empty()) mv.observed.assign(mv.labels.v.size(), 1);
      for (size_t p = 0; p < gaps_unobserved.size(); ++p)
        if (gaps_unobserved[p]) mv.observed[p] = 0;
    }
    HybridView& hv = d.views[j];
    int D = 0, gh = 0, gw = 0;
    std::vector<float> grid = *scene.load_feature_grid(idx[j], gh, gw, D);  // read once, used twice below
    if (D != d.dim)
      fail("{}: feature dimension {} differs from the first view's {}", v.feature_path->string(), D, d.dim);
    hv.zref.assign(size_t(d.num_labels) * D, 0.f);
    hv.area.assign(d.num_labels, 0.f);
    if (gh == v.height && gw == v.width)
      pool_reference(grid.data(), mv.labels, D, d.num_labels, hv.zref.data(), hv.area.data());
    else  // the grid upsampled to the view one pixel at a time (no [H, W, D] map)
      pool_reference_upsampled(grid.data(), gh, gw, mv.labels, D, d.num_labels, hv.zref.data(), hv.area.data());
    for (int l = 0; l < d.num_labels; ++l) {
      if (hv.area[l] > 0) hv.present.push_back(l);
      if (l > 0 && hv.area[l] >= cfg.min_mask_pixels) hv.fg.push_back(l);
    }
    hv.scl = scl_classes(hv.fg, hv.area[0], cfg.scl_background, cfg.min_mask_pixels);
    if (!cfg.use_scl) {
      hv.ph = gh;
      hv.pw = gw;
      hv.patch_features = std::move(grid);
    }
  });
  return d;
}

}  // namespace hgs::hybrid
