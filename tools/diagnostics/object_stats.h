// Shared by the diagnostics programs: rendered object opacity against the exact masks of a synthetic scene.
#pragma once
#include <algorithm>
#include <map>
#include <string>
#include <vector>

#include "core/image.h"
#include "eval/instances.h"
#include "query/query.h"
#include "render/camera_from_view.h"
#include "render/renderer.h"
#include "scene/scene.h"

namespace hgs::diag {

// Per object k (index = label, 0 unused) over the held-out views: sum of A_k inside and outside its exact mask,
// the inside pixel count, and intersection / union of A_k > 0.5 with the mask.
struct ObjectMaskStats {
  std::vector<double> in_sum, in_count, out_sum, inter, uni;  // [L]
  double a_in(int k) const { return in_count[k] > 0 ? in_sum[k] / in_count[k] : 0.0; }
  double iou(int k) const { return uni[k] > 0 ? inter[k] / uni[k] : 0.0; }
};

inline ObjectMaskStats object_mask_stats(const Scene& sc, const GaussianModel& m, int L,
                                         const std::map<int, std::string>& names, render::GaussianRenderer& r) {
  ObjectMaskStats s;
  for (auto* v : {&s.in_sum, &s.in_count, &s.out_sum, &s.inter, &s.uni}) v->assign(L, 0.0);
  std::vector<int> ks;
  for (int k = 1; k < L; ++k) ks.push_back(k);
  for (int vi : sc.test_indices()) {
    const View& v = sc.views[vi];
    const std::vector<float> A = query::render_object_opacity(r, m, render::camera_from_view(v), ks);  // [H, W, L - 1]
    const eval::InstanceLabels gt = eval::load_instance_masks(sc.root, v.name, names, v.width, v.height);
    for (size_t j = 0; j < gt.ids.size(); ++j) {
      const int k = gt.ids[j];
      if (k < 1 || k >= L) continue;  // an object the model has no channel for
      for (size_t p = 0; p < gt.masks[j].size(); ++p) {
        const float a = A[p * ks.size() + (k - 1)];
        const bool g = gt.masks[j][p] != 0;
        (g ? s.in_sum : s.out_sum)[k] += a;
        s.in_count[k] += g;
        s.inter[k] += g && a > 0.5f;
        s.uni[k] += g || a > 0.5f;
      }
    }
  }
  return s;
}

// The exact label map of view v (gt/instances): 0 = background, k = object k.
inline LabelMap exact_labels(const Scene& sc, const View& v, const std::map<int, std::string>& names) {
  const eval::InstanceLabels gt = eval::load_instance_masks(sc.root, v.name, names, v.width, v.height);
  LabelMap lab;
  lab.width = v.width;
  lab.height = v.height;
  lab.v.assign(size_t(v.width) * v.height, 0);
  for (size_t j = 0; j < gt.ids.size(); ++j)
    for (size_t p = 0; p < lab.v.size(); ++p)
      if (gt.masks[j][p]) lab.v[p] = static_cast<uint16_t>(gt.ids[j]);
  return lab;
}

}  // namespace hgs::diag
