// diag_object_opacity: per-object diagnostics of a trained hybrid model on a synthetic scene's held-out views:
// mean rendered object opacity A_k inside the exact mask (A_in), its sum outside (A_out), IoU of A_k > 0.5 with
// the exact mask (the object picked by id, not by text), and, over the Gaussians whose hard id is k, their count,
// mean q_{n,k} and mean opacity.
//
//   diag_object_opacity SCENE MODEL_DIR
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include "eval/instances.h"
#include "model/ply.h"
#include "query/query.h"
#include "render/renderer.h"
#include "scene/scene.h"
#include "train/trainer.h"
using namespace hgs;
int main(int argc, char** argv) try {
  if (argc < 3) {
    std::fprintf(stderr, "usage: diag_object_opacity SCENE MODEL_DIR\n");
    return 2;
  }
  Scene sc = load_scene(argv[1]);
  GaussianModel m = read_model_ply(std::string(argv[2]) + "/point_cloud.ply");
  auto names = eval::load_object_names(sc.root);
  const ExtraGroup* q = m.find_extra("obj");
  const ExtraGroup* z = m.find_extra("obj_id");
  if (!q || !z) throw std::runtime_error(std::string(argv[2]) + ": not a hybrid model (no obj / obj_id)");
  int L = q->dim;
  std::vector<int> ks; for (int k = 1; k < L; ++k) ks.push_back(k);
  std::vector<double> in_sum(L, 0), in_cnt(L, 0), out_sum(L, 0), iou_i(L,0), iou_u(L,0);
  render::GaussianRenderer r;
  for (int vi : sc.test_indices()) {
    const View& v = sc.views[vi];
    auto A = query::render_object_opacity(r, m, train::make_camera(v), ks);
    auto gt = eval::load_instance_masks(sc.root, v.name, names, v.width, v.height);
    size_t HW = size_t(v.width) * v.height;
    for (size_t j = 0; j < gt.ids.size(); ++j) {
      int k = gt.ids[j];
      for (size_t p = 0; p < HW; ++p) {
        float a = A[p * ks.size() + (k - 1)];
        bool g = gt.masks[j][p] != 0;
        if (g) { in_sum[k] += a; in_cnt[k] += 1; } else out_sum[k] += a;
        iou_i[k] += g && a > 0.5f; iou_u[k] += g || a > 0.5f;
      }
    }
  }
  // Gaussian stats by hard id
  std::vector<double> cnt(L, 0), qk(L, 0), op(L, 0);
  for (int i = 0; i < m.n; ++i) {
    int k = int(z->data[i]);
    cnt[k]++; qk[k] += q->data[size_t(i) * L + k]; op[k] += 1 / (1 + std::exp(-m.opacity_logit[i]));
  }
  printf("%-24s %8s %8s %8s %6s %8s %6s %6s\n", "object", "A_in", "px_in", "A_out", "IoU", "gauss", "q_k", "sig(o)");
  for (int k = 1; k < L; ++k)
    printf("%-24s %8.3f %8.0f %8.0f %6.1f %8.0f %6.3f %6.3f\n", names.count(k) ? names[k].c_str() : "?", in_cnt[k] ? in_sum[k] / in_cnt[k] : 0, in_cnt[k], out_sum[k], 100 * iou_i[k] / std::max(1.0, iou_u[k]), cnt[k], cnt[k] ? qk[k] / cnt[k] : 0, cnt[k] ? op[k] / cnt[k] : 0);
  printf("background gauss %.0f q0 %.3f\n", cnt[0], cnt[0] ? qk[0] / cnt[0] : 0);
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
