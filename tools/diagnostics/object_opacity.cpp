// diag_object_opacity: per-object diagnostics of a trained hybrid model on a synthetic scene's held-out views:
// mean rendered object opacity A_k inside the exact mask (A_in), its sum outside (A_out), IoU of A_k > 0.5 with
// the exact mask (the object picked by id, not by text), and, over the Gaussians whose hard id is k, their count,
// mean q_{n,k} and mean opacity.
//
//   diag_object_opacity SCENE MODEL_DIR
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include "model/ply.h"
#include "object_stats.h"
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
  render::GaussianRenderer r;
  const diag::ObjectMaskStats st = diag::object_mask_stats(sc, m, L, names, r);
  // Gaussian stats by hard id
  std::vector<double> cnt(L, 0), qk(L, 0), op(L, 0);
  for (int i = 0; i < m.n; ++i) {
    const int k = int(z->data[i]);
    if (k < 0 || k >= L) continue;
    cnt[k]++;
    qk[k] += q->data[size_t(i) * L + k];
    op[k] += 1 / (1 + std::exp(-m.opacity_logit[i]));
  }
  printf("%-24s %8s %8s %8s %6s %8s %6s %6s\n", "object", "A_in", "px_in", "A_out", "IoU", "gauss", "q_k", "sig(o)");
  for (int k = 1; k < L; ++k)
    printf("%-24s %8.3f %8.0f %8.0f %6.1f %8.0f %6.3f %6.3f\n", names.count(k) ? names[k].c_str() : "?", st.a_in(k),
           st.in_count[k], st.out_sum[k], 100 * st.iou(k), cnt[k], cnt[k] ? qk[k] / cnt[k] : 0,
           cnt[k] ? op[k] / cnt[k] : 0);
  printf("background gauss %.0f q0 %.3f\n", cnt[0], cnt[0] ? qk[0] / cnt[0] : 0);
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
