// diag_fused_evidence: Observation Fusion's evidence for one object's Gaussians. For the Gaussians whose hard id
// is K in a trained model, the mean of s_{n,l} (eq. 4 with uniform view weights) over every label l, and how
// many of them each label would win (argmax), from the scene's masks filtered at TAU1 (`background`: eq. 2 as
// written, pixels below TAU1 are background; `unobserved`: they are no observation), or from the exact
// ground-truth masks (gt/instances) with `exact`; `+visible` (e.g. unobserved+visible) adds the occlusion test
// (a view counts only where the Gaussian is not behind the surface the model renders there).
//
//   diag_fused_evidence SCENE MODEL_DIR K|@x,y,z,r [TAU1] [background|unobserved|exact][+visible]
#include <cstdio>
#include <stdexcept>
#include <string>
#include "eval/instances.h"
#include "hybrid/association.h"
#include "hybrid/data.h"
#include "hybrid/fusion.h"
#include "model/near_plane.h"
#include "model/ply.h"
#include "object_stats.h"
#include "scene/scene.h"
using namespace hgs;
int main(int argc, char** argv) try {
  if (argc < 4) {
    std::fprintf(stderr,
                 "usage: diag_fused_evidence SCENE MODEL_DIR K [TAU1] [background|unobserved|exact][+visible]\n");
    return 2;
  }
  Scene sc = load_scene(argv[1]);
  GaussianModel m = read_model_ply(std::string(argv[2]) + "/point_cloud.ply");
  // K may also be @x,y,z,r: the Gaussians whose centre lies within r of (x, y, z), whatever their hard id.
  int k = -1;
  double sel[4] = {0, 0, 0, -1};
  if (argv[3][0] == '@') {
    if (std::sscanf(argv[3] + 1, "%lf,%lf,%lf,%lf", &sel[0], &sel[1], &sel[2], &sel[3]) != 4)
      throw std::runtime_error("K must be an id or @x,y,z,r");
  } else {
    k = atoi(argv[3]);
  }
  float tau1 = argc > 4 ? atof(argv[4]) : 0.5f;
  hybrid::HybridConfig hc;
  hc.tau1 = tau1;
  auto idx = sc.train_indices();
  std::string mode = argc > 5 ? argv[5] : "background";
  bool visible = false;
  if (mode.size() > 8 && mode.substr(mode.size() - 8) == "+visible") visible = true, mode.resize(mode.size() - 8);
  if (mode != "background" && mode != "unobserved" && mode != "exact")
    throw std::runtime_error("the 5th argument must be background, unobserved or exact (each optionally +visible)");
  hc.unconfident_unobserved = mode == "unobserved";
  auto data = hybrid::load_hybrid_data(sc, idx, hc, false);
  if (mode == "exact") {
    const auto names = eval::load_object_names(sc.root);
    for (size_t j = 0; j < idx.size(); ++j) data.masks[j].labels = diag::exact_labels(sc, sc.views[idx[j]], names);
  }
  hybrid::ObservationTable tab;
  // At the plane the model was trained with (MODEL/config.json), as training's observations are.
  const float near_plane = model_near_plane(std::string(argv[2]) + "/point_cloud.ply");
  hybrid::observe(m.mean.data(), m.n, data.masks, tab, near_plane);
  if (visible) hybrid::hide_occluded_all(m, data.masks, near_plane, tab);
  int L = data.num_labels, U = tab.num_views;
  const ExtraGroup* z = m.find_extra("obj_id");
  if (!z) throw std::runtime_error(std::string(argv[2]) + ": not a hybrid model (no obj_id)");
  std::vector<double> s(L, 0);
  int cnt = 0;
  std::vector<int> win(L, 0), hard(L, 0);
  double nv = 0;
  for (int i = 0; i < m.n; ++i) {
    if (sel[3] > 0) {
      const float* c = &m.mean[size_t(i) * 3];
      const double dx = c[0] - sel[0], dy = c[1] - sel[1], dz = c[2] - sel[2];
      if (dx * dx + dy * dy + dz * dz > sel[3] * sel[3]) continue;
    } else if (int(z->data[i]) != k) {
      continue;
    }
    std::vector<double> si(L, 0);
    double den = 0;
    for (int u = 0; u < U; ++u) {
      auto l = tab.label[size_t(i) * U + u];
      if (l == hybrid::kNoObservation) continue;
      den++;
      si[l]++;
    }
    const int zi = int(z->data[i]);
    if (zi >= 0 && zi < L) hard[zi]++;
    if (den == 0) continue;
    cnt++;
    nv += den;
    int best = 0;
    for (int l = 0; l < L; ++l) {
      s[l] += si[l] / den;
      if (si[l] > si[best]) best = l;
    }
    win[best]++;
  }
  if (cnt == 0) {
    printf("object %d: no Gaussian has this hard id\n", k);
    return 0;
  }
  printf("object %d: %d Gaussians, mean valid views %.1f\n  mean s:", k, cnt, nv / cnt);
  for (int l = 0; l < L; ++l) printf(" %d:%.3f", l, s[l] / cnt);
  printf("\n  model's hard ids:");
  for (int l = 0; l < L; ++l) printf(" %d:%d", l, hard[l]);
  printf("\n  argmax:");
  for (int l = 0; l < L; ++l) printf(" %d:%d", l, win[l]);
  printf("\n");
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
