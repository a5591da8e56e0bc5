// diag_bro_landscape: eq. 6 and eq. 14 along each object's amplitude, the evidence for BRO's scale-invariant
// gradient (hybrid/bro.h, docs/results.md). For every object k and factor s, the object render I_k and opacity
// A_k of a trained model are scaled by s (as scaling every q_{n,k} would), and eq. 6 and eq. 14 (band from the
// scaled A_k and the mask, 5x5) are averaged over the training views whose mask holds k.
//
//   diag_bro_landscape SCENE MODEL_DIR [noisy|noconf|exact|exactconf] [KERNEL]
// noisy: the scene's masks filtered at tau1 = 0.5 (what training sees); noconf: the same masks without the
// confidence filter; exact / exactconf: the synthetic ground truth gt/instances (then filtered).
#include <cmath>
#include <cstdio>
#include <cstring>
#include <stdexcept>
#include "eval/instances.h"
#include "hybrid/bro.h"
#include "hybrid/data.h"
#include "model/ply.h"
#include "model/render_inputs.h"
#include "object_stats.h"
#include "render/camera_from_view.h"
#include "render/renderer.h"
#include "render/sh.h"
#include "scene/scene.h"
#include "train/loss.h"
using namespace hgs;
int main(int argc, char** argv) try {
  if (argc < 3) {
    std::fprintf(stderr, "usage: diag_bro_landscape SCENE MODEL_DIR [noisy|noconf|exact|exactconf] [KERNEL]\n");
    return 2;
  }
  Scene sc = load_scene(argv[1]);
  GaussianModel m = read_model_ply(std::string(argv[2]) + "/point_cloud.ply");
  std::string mode = argc > 3 ? argv[3] : "noisy";
  if (mode != "noisy" && mode != "noconf" && mode != "exact" && mode != "exactconf")
    throw std::runtime_error("mode must be noisy, noconf, exact or exactconf");
  bool exact = mode == "exact" || mode == "exactconf";
  int kernel = argc > 4 ? atoi(argv[4]) : 5;
  auto names = eval::load_object_names(sc.root);
  hybrid::HybridConfig hc;
  if (mode == "noconf") hc.tau1 = 0;
  auto idx = sc.train_indices();
  hybrid::HybridData data = hybrid::load_hybrid_data(sc, idx, hc, false);
  const ExtraGroup* qg = m.find_extra("obj");
  int L = qg->dim, n = m.n;
  std::vector<float> scales = {0.5f, 0.75f, 0.9f, 1.0f, 1.1f};
  int S = scales.size();
  // per object, per scale: sum of app and bro losses, count
  std::vector<double> app(L * S, 0), bro(L * S, 0), cnt(L, 0);
  render::GaussianRenderer r;
  train::PhotometricLoss pl(0.2f);
  for (size_t vi = 0; vi < idx.size(); ++vi) {
    const View& v = sc.views[idx[vi]];
    auto cam = render::camera_from_view(v);
    Image img = sc.load_image(idx[vi]);
    LabelMap lab = data.masks[vi].labels;
    if (exact) {
      lab = diag::exact_labels(sc, v, names);
      if (mode == "exactconf")
        if (auto conf = sc.load_confidence(idx[vi])) hybrid::apply_confidence(lab, *conf, 0.5f);
    }
    float campos[3];
    for (int c = 0; c < 3; ++c) campos[c] = -(cam.R[c] * cam.t[0] + cam.R[3 + c] * cam.t[1] + cam.R[6 + c] * cam.t[2]);
    std::vector<float> col(size_t(n) * 3);
    render::sh_forward(n, m.sh_degree, m.sh_stride(), m.sh.data(), m.mean.data(), campos, (const int*)nullptr,
                       col.data());
    std::vector<int> present;
    std::vector<int> area(L, 0);
    for (auto l : lab.v) area[l]++;
    for (int k = 1; k < L; ++k)
      if (area[k] > 0) present.push_back(k);
    int J = present.size(), C = 4 * J;
    std::vector<float> extra(size_t(n) * C);
    for (int i = 0; i < n; ++i)
      for (int j = 0; j < J; ++j) {
        float q = qg->data[size_t(i) * L + present[j]];
        for (int c = 0; c < 3; ++c) extra[size_t(i) * C + 3 * j + c] = q * col[i * 3 + c];
        extra[size_t(i) * C + 3 * J + j] = q;
      }
    auto in = render_inputs(m);
    in.colors = col.data();
    in.extra = extra.data();
    in.num_extra = C;
    render::RenderSettings rs;
    rs.want_depth = false;
    render::RenderOutputs out;
    r.forward(cam, in, rs, out);
    int W = v.width, H = v.height;
    size_t HW = size_t(W) * H;
    std::vector<float> pred(HW * 3), gtk(HW * 3), A(HW), M(HW), B(HW);
    for (int j = 0; j < J; ++j) {
      int k = present[j];
      cnt[k] += 1;
      for (size_t p = 0; p < HW; ++p) {
        M[p] = lab.v[p] == k;
        for (int c = 0; c < 3; ++c) gtk[p * 3 + c] = img.px[p * 3 + c] * M[p];
      }
      for (int si = 0; si < S; ++si) {
        float s = scales[si];
        for (size_t p = 0; p < HW; ++p) {
          for (int c = 0; c < 3; ++c) pred[p * 3 + c] = s * out.extra[p * C + 3 * j + c];
          A[p] = s * out.extra[p * C + 3 * J + j];
        }
        app[k * S + si] += pl(pred.data(), gtk.data(), H, W, nullptr).total;
        hybrid::boundary_band(A.data(), M.data(), H, W, kernel, B.data());
        bro[k * S + si] += hybrid::bro_loss<float>(pred.data(), gtk.data(), 3, 3, B.data(), H, W, 1e-6f, nullptr, 1.f);
      }
    }
  }
  printf("%-22s %5s |", "object", "views");
  for (float s : scales) printf("  app(%.2f)", s);
  printf(" |");
  for (float s : scales) printf("  bro(%.2f)", s);
  printf("\n");
  for (int k = 1; k < L; ++k) {
    printf("%-22s %5.0f |", names[k].c_str(), cnt[k]);
    for (int si = 0; si < S; ++si) printf(" %10.5f", app[k * S + si] / cnt[k]);
    printf(" |");
    for (int si = 0; si < S; ++si) printf(" %10.5f", bro[k * S + si] / cnt[k]);
    printf("\n");
  }
  return 0;
} catch (const std::exception& e) {
  std::fprintf(stderr, "error: %s\n", e.what());
  return 1;
}
