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
#include "hybrid/config.h"
#include "hybrid/register.h"
#include "object_stats.h"
#include "query/query.h"
#include "scene/scene.h"
#include "train/registry.h"
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
  hybrid::register_method();
  auto tr = train::make_trainer(sc, sc.train_indices(), cfg, "hybrid", hc.to_json(), false);
  auto names = eval::load_object_names(sc.root);
  render::GaussianRenderer r;
  for (int it = 1; it <= iters; ++it) {
    tr->step();
    if (it % every) continue;
    const GaussianModel& m = tr->model();
    const ExtraGroup* q = m.find_extra("obj");
    const ExtraGroup* z = m.find_extra("obj_id");
    int L = q->dim;
    const diag::ObjectMaskStats st = diag::object_mask_stats(sc, m, L, names, r);
    std::vector<int> cnt(L, 0);
    for (int i = 0; i < m.n; ++i)
      if (int(z->data[i]) < L) cnt[int(z->data[i])]++;
    const train::MethodStats ms = tr->method().stats();
    const std::vector<float>& w = ms.array("view_weights");
    double wmax = 0, wmin = 1, ent = 0;
    for (float x : w) {
      wmax = std::max<double>(wmax, x);
      wmin = std::min<double>(wmin, x);
      ent -= x > 0 ? x * std::log(x) : 0;
    }
    printf("it %5d N %6d app %.4f bro %.4f sem %.3f | w %.4f..%.4f H/Hmax %.3f | A_in:", it, m.n, ms.value("app"),
           ms.value("bro"), ms.value("sem"), wmin, wmax, ent / std::log(double(w.size())));
    double miou = 0;
    for (int k = 1; k < L; ++k) {
      printf(" %.2f", st.a_in(k));
      miou += st.iou(k);
    }
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
