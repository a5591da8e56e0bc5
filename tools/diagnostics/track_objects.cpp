// diag_track_objects: trains a hybrid model and prints, every EVERY iterations, the loss terms, the spread of the
// view weights, each object's mean rendered opacity inside its exact mask on the held-out views (A_in), the
// number of Gaussians whose hard id is each object (nz) and the IoU of A_k > 0.5 (objects picked by id).
//
//   diag_track_objects SCENE ITERS EVERY [nobro] [noscl] [noof] [plainbro] [semgeom] [lrview=X] [lbro=X]
//                      [kernel=X] [lrgb=X] [T=X]
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include <string>
#include "eval/instances.h"
#include "hybrid/setup.h"
#include "hybrid/trainer.h"
#include "query/query.h"
#include "scene/scene.h"
using namespace hgs;
int main(int argc, char** argv) try {
  if (argc < 4) {
    std::fprintf(stderr, "usage: diag_track_objects SCENE ITERS EVERY [options]\n");
    return 2;
  }
  Scene sc = load_scene(argv[1]);
  int iters = atoi(argv[2]), every = atoi(argv[3]);
  train::TrainConfig cfg;
  cfg = cfg.scaled_to(iters);
  hybrid::HybridConfig hc;
  for (int a = 4; a < argc; ++a) {
    std::string s = argv[a];
    auto val = [&]() { return std::stof(s.substr(s.find('=') + 1)); };
    if (s == "nobro") hc.use_bro = false;
    else if (s == "noscl") hc.use_scl = false;
    else if (s == "noof") hc.use_of = false;
    else if (s == "plainbro") hc.bro_scale_invariant = false;
    else if (s == "semgeom") hc.sem_geometry = true;
    else if (s.rfind("T=", 0) == 0) hc.temperature = val();
    else if (s.rfind("lrview=", 0) == 0) hc.lr_view = val();
    else if (s.rfind("lbro=", 0) == 0) hc.lambda_bro = val();
    else if (s.rfind("kernel=", 0) == 0) hc.bro_kernel = int(val());
    else if (s.rfind("lrgb=", 0) == 0) hc.lambda_rgb = val();
    else throw std::runtime_error("unknown option " + s);
  }
  if (iters < 1 || every < 1) throw std::runtime_error("ITERS and EVERY must be positive");
  auto tr = hybrid::make_trainer(sc, sc.train_indices(), cfg, hc, false);
  auto& ht = dynamic_cast<hybrid::HybridTrainer&>(*tr);
  auto names = eval::load_object_names(sc.root);
  render::GaussianRenderer r;
  for (int it = 1; it <= iters; ++it) {
    tr->step();
    if (it % every) continue;
    const GaussianModel& m = tr->model();
    const ExtraGroup* q = m.find_extra("obj");
    const ExtraGroup* z = m.find_extra("obj_id");
    int L = q->dim;
    std::vector<int> ks; for (int k = 1; k < L; ++k) ks.push_back(k);
    std::vector<double> in_sum(L, 0), in_cnt(L, 0), ii(L, 0), uu(L, 0);
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
          if (g) { in_sum[k] += a; in_cnt[k] += 1; }
          ii[k] += g && a > 0.5f; uu[k] += g || a > 0.5f;
        }
      }
    }
    std::vector<int> cnt(L, 0);
    for (int i = 0; i < m.n; ++i) cnt[int(z->data[i])]++;
    const auto& w = ht.view_weights();
    double wmax = 0, wmin = 1, ent = 0;
    for (float x : w) { wmax = std::max<double>(wmax, x); wmin = std::min<double>(wmin, x); ent -= x > 0 ? x * std::log(x) : 0; }
    const auto& ls = ht.last_losses();
    printf("it %5d N %6d app %.4f bro %.4f sem %.3f | w %.4f..%.4f H/Hmax %.3f | A_in:", it, m.n, ls.app, ls.bro, ls.sem, wmin, wmax, ent / std::log(double(w.size())));
    double miou = 0;
    for (int k = 1; k < L; ++k) { printf(" %.2f", in_cnt[k] ? in_sum[k] / in_cnt[k] : 0); miou += uu[k] ? ii[k] / uu[k] : 0; }
    printf(" | nz:");
    for (int k = 1; k < L; ++k) printf(" %d", cnt[k]);
    printf(" | IoU %.1f\n", 100 * miou / (L - 1));
    fflush(stdout);
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
