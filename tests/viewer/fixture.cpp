#include "fixture.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <vector>

#include "core/error.h"
#include "core/image.h"
#include "model/gaussian_model.h"
#include "model/ply.h"
#include "scene/scene.h"
#include "test_util.h"

namespace hgs::test {
namespace fs = std::filesystem;

ViewerFixture make_viewer_fixture(const fs::path& dir) {
  ViewerFixture f;
  f.scene = dir / "scene";
  f.model = dir / "model.ply";
  RunResult r = run_hgs("synth --out '" + f.scene.string() +
                        "' --views 16 --width 96 --height 72 --objects 4 --points 3000 --feature-dim 32 "
                        "--supersample 1 --quiet");
  if (r.exit_code != 0) fail("hgs synth failed: {}", r.err);
  Scene s = load_scene(f.scene);
  f.names = s.object_names;
  const int K = s.num_objects();
  GaussianModel m = init_from_points(s.points, s.point_colors, 0);
  const int N = m.n;
  std::fill(m.opacity_logit.begin(), m.opacity_logit.end(), inverse_sigmoid(0.9f));
  // Majority ground-truth object over the views where the point projects inside the image.
  std::vector<int> votes(size_t(N) * (K + 1), 0);
  for (const View& v : s.views) {
    LabelMap gt = load_label_png(f.scene / "gt" / "instances" / (v.stem + ".png"));
    for (int i = 0; i < N; ++i) {
      const Eigen::Vector3d p = v.R * s.points[i].cast<double>() + v.t;
      if (p.z() <= 1e-6) continue;
      const int x = int(v.fx * p.x() / p.z() + v.cx), y = int(v.fy * p.y() / p.z() + v.cy);
      if (x < 0 || y < 0 || x >= gt.width || y >= gt.height) continue;
      const int k = gt.at(x, y);
      if (k <= K) votes[size_t(i) * (K + 1) + k]++;
    }
  }
  const int D = int(s.text_embeddings.begin()->second.size());
  // (References taken after the last add_extra: each may reallocate m.extras.)
  m.add_extra("obj", K + 1);
  m.add_extra("obj_id", 1);
  m.add_extra("lang", D);
  ExtraGroup &q = *m.find_extra("obj"), &z = *m.find_extra("obj_id"), &lang = *m.find_extra("lang");
  for (int i = 0; i < N; ++i) {
    const int* vi = &votes[size_t(i) * (K + 1)];
    const int k = int(std::max_element(vi, vi + K + 1) - vi);
    q.data[size_t(i) * (K + 1) + k] = 1.f;
    z.data[i] = float(k);
    f.counts[k]++;
    if (k == 0) continue;
    const std::vector<float>& e = s.text_embeddings.at(s.object_names.at(k));
    std::copy(e.begin(), e.end(), lang.data.begin() + size_t(i) * D);
  }
  write_model_ply(f.model, m);
  return f;
}

}  // namespace hgs::test
