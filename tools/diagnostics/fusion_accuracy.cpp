// diag_fusion_accuracy: how well Observation Fusion recovers each Gaussian's object from the scene's noisy masks.
// Reference: the label eq. 4 gives (uniform view weights) from the exact ground-truth masks (gt/instances) with
// the occlusion test. Compared: eq. 4 on the noisy masks filtered at TAU1 (unconfident pixels no observation) as
// written, and with the mask-noise model (label_evidence). Per reference label: how many Gaussians, opacity-
// weighted recall (share of that label's opacity given the right label), and the labels wrongly given.
//
//   diag_fusion_accuracy SCENE MODEL_DIR [TAU1] [visible]   (visible: the occlusion test on the noisy side too)
// OUT: writes OUT_eq4/ and OUT_noise/, the model with each decision, for hgs eval.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <stdexcept>
#include <string>

#include "eval/instances.h"
#include "hybrid/association.h"
#include "hybrid/data.h"
#include "hybrid/fields.h"
#include "hybrid/fusion.h"
#include "model/ply.h"
#include "object_stats.h"
#include "scene/scene.h"
using namespace hgs;

namespace {
std::vector<uint16_t> decide(const hybrid::ObservationTable& tab, int L, const float* evidence) {
  std::vector<float> w(tab.num_views, 1.f / tab.num_views), q(size_t(tab.n) * L, 0.f), s(q.size());
  std::vector<uint8_t> valid(tab.n);
  hybrid::FusionParams p{L, 0.05, 1e-6, evidence};
  hybrid::fuse(tab, w.data(), p, q.data(), s.data(), valid.data());
  std::vector<uint16_t> z(tab.n);
  hybrid::hard_ids(s.data(), tab.n, L, z.data());
  for (int n = 0; n < tab.n; ++n)
    if (!valid[n]) z[n] = hybrid::kNoObservation;
  return z;
}
}  // namespace

int main(int argc, char** argv) try {
  if (argc < 3) {
    std::fprintf(stderr, "usage: diag_fusion_accuracy SCENE MODEL_DIR [TAU1] [visible|all] [OUT]\n");
    return 2;
  }
  Scene sc = load_scene(argv[1]);
  GaussianModel m = read_model_ply(std::string(argv[2]) + "/point_cloud.ply");
  hybrid::HybridConfig hc;
  hc.tau1 = argc > 3 ? float(atof(argv[3])) : 0.5f;
  auto idx = sc.train_indices();
  auto noisy = hybrid::load_hybrid_data(sc, idx, hc, false);
  auto exact = noisy;
  const auto names = eval::load_object_names(sc.root);
  for (size_t j = 0; j < idx.size(); ++j) {
    exact.masks[j].labels = diag::exact_labels(sc, sc.views[idx[j]], names);
    exact.masks[j].observed.clear();
  }
  const int L = noisy.num_labels;
  hybrid::ObservationTable tn, te;
  hybrid::observe(m.mean.data(), m.n, noisy.masks, tn);
  hybrid::observe(m.mean.data(), m.n, exact.masks, te);
  hybrid::hide_occluded_all(m, exact.masks, te);
  const auto ref = decide(te, L, nullptr);
  const bool visible = argc > 4 && std::string(argv[4]) == "visible";
  if (visible) hybrid::hide_occluded_all(m, noisy.masks, tn);
  const auto plain = decide(tn, L, nullptr);
  const auto ev = hybrid::label_evidence(tn, L);
  const auto model = decide(tn, L, ev.data());
  std::printf("evidence [observed j -> vote for k], rows j = 0..%d:\n", L - 1);
  for (int j = 0; j < L; ++j) {
    std::printf("  %2d:", j);
    for (int k = 0; k < L; ++k) std::printf(" %.2f", ev[size_t(j) * L + k]);
    std::printf("\n");
  }
  std::printf("label  gaussians  recall(eq.4)  recall(noise model)  prec.(eq.4)  prec.(noise model)  [opacity-weighted; reference = exact masks]\n");
  double tot[3] = {0, 0, 0};
  for (int k = 0; k < L; ++k) {
    double mass = 0, hit_plain = 0, hit_model = 0, given_plain = 0, given_model = 0;
    int cnt = 0;
    for (int n = 0; n < m.n; ++n) {
      const double a = 1.0 / (1.0 + std::exp(-m.opacity_logit[n]));
      given_plain += plain[n] == k ? a : 0;
      given_model += model[n] == k ? a : 0;
      if (ref[n] != k) continue;
      cnt++;
      mass += a;
      hit_plain += plain[n] == k ? a : 0;
      hit_model += model[n] == k ? a : 0;
    }
    if (!cnt) continue;
    tot[0] += mass, tot[1] += hit_plain, tot[2] += hit_model;
    std::printf("%5d  %9d  %12.3f  %19.3f  %12.3f  %19.3f\n", k, cnt, hit_plain / mass, hit_model / mass,
                hit_plain / std::max(given_plain, 1e-9), hit_model / std::max(given_model, 1e-9));
  }
  std::printf("  all  %9s  %12.3f  %19.3f\n", "", tot[1] / tot[0], tot[2] / tot[0]);
  // With OUT: OUT_eq4/ and OUT_noise/ hold the model with q one-hot at each decision (unobserved Gaussians keep
  // theirs), for `hgs eval` on the same geometry.
  if (argc > 5) {
    for (int variant = 0; variant < 2; ++variant) {
      GaussianModel c = m;
      auto h = hybrid::HybridFields::bind(c, "model");
      const auto& z = variant == 0 ? plain : model;
      for (int n = 0; n < c.n; ++n) {
        if (z[n] == hybrid::kNoObservation) continue;
        for (int k = 0; k < L; ++k) h.q->data[size_t(n) * L + k] = k == z[n] ? 1.f : 0.f;
        h.z->data[n] = float(z[n]);
      }
      const std::filesystem::path out = std::string(argv[5]) + (variant == 0 ? "_eq4" : "_noise");
      std::filesystem::create_directories(out);
      write_model_ply(out / "point_cloud.ply", c);
      std::filesystem::copy_file(std::filesystem::path(argv[2]) / "config.json", out / "config.json",
                                 std::filesystem::copy_options::overwrite_existing);
    }
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
