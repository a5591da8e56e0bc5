// Label boxes for the fragment rule (fragments.h): per label, the 5th and 95th percentile of its opaque
// Gaussians' centres on each axis (nth_element on each axis's values), robust to a few stray Gaussians.
#include "query/fragments.h"

#include <algorithm>

#include "hybrid/fields.h"

namespace hgs::query {

std::vector<LabelBox> label_boxes(const GaussianModel& m, int L) {
  const auto h = hybrid::ConstHybridFields::bind(m, "query");
  std::vector<std::vector<int>> members(L);  // [L] Gaussians of each label
  for (int i = 0; i < m.n; ++i) {
    const int z = static_cast<int>(h.z->data[i]);
    if (z >= 0 && z < L && sigmoid(m.opacity_logit[i]) > 0.3f) members[z].push_back(i);
  }
  std::vector<LabelBox> boxes(L);
  std::vector<float> v;
  for (int k = 0; k < L; ++k) {
    const auto& g = members[k];
    if (g.size() < 5) continue;
    for (int a = 0; a < 3; ++a) {
      v.resize(g.size());
      for (size_t j = 0; j < g.size(); ++j) v[j] = m.mean[size_t(g[j]) * 3 + a];
      const size_t lo = (v.size() - 1) * 5 / 100, hi = (v.size() - 1) * 95 / 100;
      std::nth_element(v.begin(), v.begin() + lo, v.end());
      boxes[k].lo[a] = v[lo];
      std::nth_element(v.begin(), v.begin() + hi, v.end());
      boxes[k].hi[a] = v[hi];
    }
    boxes[k].valid = true;
  }
  return boxes;
}

bool boxes_meet(const LabelBox& a, const LabelBox& b) {
  if (!a.valid || !b.valid) return false;
  for (int i = 0; i < 3; ++i) {
    const float ga = 0.2f * (a.hi[i] - a.lo[i]), gb = 0.2f * (b.hi[i] - b.lo[i]);
    if (a.lo[i] - ga > b.hi[i] + gb || b.lo[i] - gb > a.hi[i] + ga) return false;
  }
  return true;
}

}  // namespace hgs::query
