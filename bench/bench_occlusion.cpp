// The occlusion test of Observation Fusion (hybrid/association.h, run at every observation-table rebuild: one
// per training view) on a trained model of a real capture: the test as it was, a whole depth render per view and
// the surface at every pixel, against the test as it is, the depth composited at the observed centres' pixels
// only (render::RendererT::depth_at). The two alternate for a few rounds on the same views; the tables they leave
// must be equal (the program fails otherwise). Every pixel of every view counts as observed, label 1, so every
// centre in front of a camera is tested. Prints the ms per view of each (median and minimum over the rounds), the
// share of pixels the test reads and the entries it hides.
//   build/bench_occlusion SCENE MODEL.ply [--views N] [--rounds R] [--threads T]
#include <omp.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "core/error.h"
#include "hybrid/association.h"
#include "hybrid/data.h"
#include "hybrid/fusion.h"
#include "model/near_plane.h"
#include "model/ply.h"
#include "model/render_inputs.h"
#include "render/camera_from_view.h"
#include "scene/scene.h"

using namespace hgs;

namespace {

double now_ms() {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

// The test as it was before RendererT::depth_at: a whole render of depth and alpha, the surface at every pixel.
void occlusion_whole_renders(const GaussianModel& m, const std::vector<hybrid::MaskView>& views, float near_plane,
                             hybrid::ObservationTable& table, render::GaussianRenderer& r, render::RenderOutputs& out,
                             std::vector<float>& surface) {
  render::GaussianInputs in = render_inputs(m);
  in.sh_degree = 0;
  render::RenderSettings rs;
  rs.want_depth = true;
  for (size_t u = 0; u < views.size(); ++u) {
    const hybrid::MaskView& v = views[u];
    r.forward(render::pinhole_camera(v.width, v.height, v.fx, v.fy, v.cx, v.cy, v.R, v.t, near_plane), in, rs, out);
    surface.resize(out.alpha.size());
    const long P = long(surface.size());
#pragma omp parallel for schedule(static)
    for (long p = 0; p < P; ++p) surface[p] = out.alpha[p] > 0.5f ? out.depth[p] / out.alpha[p] : 0.f;
    hybrid::hide_occluded(m.mean.data(), m.n, v, surface.data(), int(u), table);
  }
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

int run(int argc, char** argv) {
  if (argc < 3 || std::string(argv[1]) == "--help") {
    std::printf("usage: bench_occlusion SCENE MODEL.ply [--views N] [--rounds R] [--threads T]\n");
    return argc < 3 ? 2 : 0;
  }
  int max_views = 1 << 30, rounds = 3, threads = 0;
  for (int i = 3; i < argc; ++i) {
    const std::string k = argv[i];
    if (i + 1 >= argc) fail("bench_occlusion: {} needs a value", k);
    const int v = std::atoi(argv[++i]);
    if (v < 1) fail("bench_occlusion: {} {}: a positive number is needed", k, argv[i]);
    if (k == "--views") max_views = v;
    else if (k == "--rounds") rounds = v;
    else if (k == "--threads") threads = v;
    else fail("bench_occlusion: unknown option {}", k);
  }
  if (threads > 0) omp_set_num_threads(threads);
  const Scene scene = load_scene(argv[1]);
  const GaussianModel m = read_model_ply(argv[2]);
  const float near_plane = model_near_plane(argv[2]);
  std::vector<hybrid::MaskView> views;
  size_t pixels = 0;
  for (const View& sv : scene.views) {
    if (sv.is_test || int(views.size()) >= max_views) continue;
    hybrid::MaskView v = hybrid::mask_view_geometry(sv);
    v.labels = LabelMap(sv.width, sv.height, 1);
    pixels += size_t(sv.width) * sv.height;
    views.push_back(std::move(v));
  }
  if (views.empty()) fail("bench_occlusion: {} has no training view", argv[1]);
  hybrid::ObservationTable observed;
  hybrid::observe(m.mean.data(), m.n, views, observed, near_plane);
  render::GaussianRenderer r;
  render::RenderOutputs out;
  std::vector<float> surface;
  hybrid::OcclusionScratch scratch;
  std::vector<double> old_ms, new_ms;
  hybrid::ObservationTable a, b;
  for (int round = 0; round < rounds; ++round) {
    a = observed;
    double t0 = now_ms();
    occlusion_whole_renders(m, views, near_plane, a, r, out, surface);
    old_ms.push_back((now_ms() - t0) / double(views.size()));
    b = observed;
    t0 = now_ms();
    hybrid::hide_occluded_all(m, views, near_plane, b, &scratch);
    new_ms.push_back((now_ms() - t0) / double(views.size()));
    if (a.label != b.label) fail("bench_occlusion: the two tests left different tables (round {})", round + 1);
  }
  long tested = 0, hidden = 0;
  for (size_t e = 0; e < observed.label.size(); ++e) {
    tested += observed.label[e] != hybrid::kNoObservation;
    hidden += observed.label[e] != hybrid::kNoObservation && b.label[e] == hybrid::kNoObservation;
  }
  // The pixels the test reads, over every view (what the last view's pixels were is in the scratch; count again).
  size_t chosen = 0;
  for (size_t u = 0; u < views.size(); ++u) {
    std::vector<uint8_t> c(size_t(views[u].width) * views[u].height, 0);
    hybrid::occlusion_pixels(m.mean.data(), m.n, views[u], int(u), observed, c.data());
    for (uint8_t x : c) chosen += x;
  }
  std::printf("%d Gaussians, %zu views (%dx%d first), %d threads, %d rounds: tables equal\n", m.n, views.size(),
              views[0].width, views[0].height, omp_get_max_threads(), rounds);
  std::printf("pixels read by the test: %.1f %%; entries tested %ld, hidden %ld (%.1f %%)\n",
              100.0 * double(chosen) / double(pixels), tested, hidden, 100.0 * double(hidden) / double(tested));
  std::printf("ms per view, median (min): whole renders %.1f (%.1f), depth_at %.1f (%.1f); %.2fx\n", median(old_ms),
              *std::min_element(old_ms.begin(), old_ms.end()), median(new_ms),
              *std::min_element(new_ms.begin(), new_ms.end()), median(old_ms) / median(new_ms));
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return run(argc, argv);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "%s\n", e.what());
    return 1;
  }
}
