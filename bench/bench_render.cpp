// Benchmarks of the CPU rasterizer at 320x240 with 30k Gaussians, SH degree 3 (times in ms, wall clock, at 1
// and 2 OpenMP threads). Scene: a camera at the origin looking down +z (fx = fy = 300, so ~56 deg horizontal FOV) and
// 30k Gaussians uniform in the box x in [-2.5, 2.5], y in [-1.9, 1.9], z in [3, 7] (the box fills the view),
// anisotropic scales exp(U[log 0.01, log 0.06]) per axis (1-4 px sigma on screen), random rotations, opacity
// U[0.05, 0.95], SH coefficients N(0, 0.5) for DC and N(0, 0.1) above. Counters: composited/px = Gaussians a
// pixel composites on average (alpha >= 1/255, before the T cut-off), depth/px = how far into its tile's depth
// list a pixel reads on average, pairs = (tile, Gaussian) pairs made by the binning.
//   build-<you>/bench_render --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>
#include <vector>

#include "render/binning.h"
#include "render/project.h"
#include "render/rasterize.h"
#include "render/renderer.h"
#include "render/sh.h"

#include "bench_threads.h"

using namespace hgs::render;
namespace bench = hgs::bench;

namespace {

struct BenchScene {
  Camera cam;
  int n = 30000;
  std::vector<float> mean, log_scale, quat, opacity_logit, sh;
  GaussianInputs g;
  RenderSettings rs;
  BenchScene() {
    cam.width = 320;
    cam.height = 240;
    cam.fx = cam.fy = 300;
    cam.cx = 160;
    cam.cy = 120;
    std::mt19937 rng(1234);
    std::uniform_real_distribution<float> U(0, 1);
    std::normal_distribution<float> N01(0, 1);
    for (int i = 0; i < n; ++i) {
      mean.insert(mean.end(), {-2.5f + 5 * U(rng), -1.9f + 3.8f * U(rng), 3 + 4 * U(rng)});
      for (int k = 0; k < 3; ++k) log_scale.push_back(std::log(0.01f) + (std::log(0.06f) - std::log(0.01f)) * U(rng));
      for (int k = 0; k < 4; ++k) quat.push_back(N01(rng));
      const float o = 0.05f + 0.9f * U(rng);
      opacity_logit.push_back(std::log(o / (1 - o)));
      for (int k = 0; k < 16; ++k)
        for (int c = 0; c < 3; ++c) sh.push_back(k == 0 ? 0.5f * N01(rng) : 0.1f * N01(rng));
    }
    g.n = n;
    g.mean = mean.data();
    g.log_scale = log_scale.data();
    g.quat = quat.data();
    g.opacity_logit = opacity_logit.data();
    g.sh = sh.data();
    g.sh_stride = 16;
    g.sh_degree = 3;
    rs.background[0] = rs.background[1] = rs.background[2] = 0;
  }
};

BenchScene& scene() {
  static BenchScene s;
  return s;
}

// Stage-level state shared by the stage benchmarks.
struct Stages {
  CameraT<float> cam;
  std::vector<float> mean2d, conic, depth, opacity, colors;
  std::vector<int> radius;
  Binning bins;
  RasterWorkspace<float> ws;
  std::vector<float> rgb, alpha, dep, finalT;
  std::vector<int32_t> last;
  RasterInputs<float> in;
  RasterOutputs<float> out;
  explicit Stages(const BenchScene& s) {
    const int n = s.n;
    cam = make_camera<float>(s.cam);
    mean2d.resize(2 * n), conic.resize(3 * n), depth.resize(n), opacity.resize(n), colors.resize(3 * n);
    radius.resize(n);
    project_forward(cam, n, s.mean.data(), s.log_scale.data(), s.quat.data(), mean2d.data(), conic.data(), depth.data(),
                    radius.data());
    for (int i = 0; i < n; ++i) opacity[i] = 1 / (1 + std::exp(-s.opacity_logit[i]));
    sh_forward(n, 3, 16, s.sh.data(), s.mean.data(), cam.campos, radius.data(), colors.data());
    bin_gaussians(s.cam.width, s.cam.height, n, mean2d.data(), conic.data(), opacity.data(), depth.data(),
                  radius.data(), bins);
    const size_t P = size_t(s.cam.width) * s.cam.height;
    rgb.resize(3 * P), alpha.resize(P), dep.resize(P), finalT.resize(P), last.resize(P);
    in.width = s.cam.width, in.height = s.cam.height, in.n = n;
    in.mean2d = mean2d.data(), in.conic = conic.data(), in.opacity = opacity.data(), in.color = colors.data();
    in.depth = depth.data();
    out.rgb = rgb.data(), out.alpha = alpha.data(), out.depth = dep.data(), out.final_T = finalT.data();
    out.last = last.data();
  }
};

Stages& stages() {
  static Stages st(scene());
  return st;
}

void BM_Project(benchmark::State& state) {
  const bench::OmpThreads threads(state, 0);
  BenchScene& s = scene();
  Stages& st = stages();
  for (auto _ : state)
    project_forward(st.cam, s.n, s.mean.data(), s.log_scale.data(), s.quat.data(), st.mean2d.data(), st.conic.data(),
                    st.depth.data(), st.radius.data());
}

void BM_ShForward(benchmark::State& state) {
  const bench::OmpThreads threads(state, 0);
  BenchScene& s = scene();
  Stages& st = stages();
  for (auto _ : state)
    sh_forward(s.n, 3, 16, s.sh.data(), s.mean.data(), st.cam.campos, st.radius.data(), st.colors.data());
}

void BM_ShBackward(benchmark::State& state) {
  const bench::OmpThreads threads(state, 0);
  BenchScene& s = scene();
  Stages& st = stages();
  std::vector<float> dcolors(3 * s.n), dsh(s.sh.size()), dmean(3 * s.n);
  for (size_t i = 0; i < dcolors.size(); ++i) dcolors[i] = 0.01f * float(i % 7) - 0.03f;
  for (auto _ : state)
    sh_backward(s.n, 3, 16, s.sh.data(), s.mean.data(), st.cam.campos, st.radius.data(), dcolors.data(), dsh.data(),
                dmean.data());
}

void BM_Binning(benchmark::State& state) {
  const bench::OmpThreads threads(state, 0);
  BenchScene& s = scene();
  Stages& st = stages();
  for (auto _ : state)
    bin_gaussians(s.cam.width, s.cam.height, s.n, st.mean2d.data(), st.conic.data(), st.opacity.data(), st.depth.data(),
                  st.radius.data(), st.bins);
  state.counters["pairs"] = st.bins.num_pairs;
}

// Average number of Gaussians a pixel composites (alpha >= 1/255, before the T cut-off), by a scalar replay of
// the 3DGS per-pixel loop over the tile lists.
double composited_per_pixel(const Stages& st) {
  const Binning& b = st.bins;
  double total = 0;
  for (int y = 0; y < b.height; ++y)
    for (int x = 0; x < b.width; ++x) {
      const int t = (y / kTileSize) * b.tiles_x + x / kTileSize;
      double T = 1;
      for (int e = b.tile_start[t]; e < b.tile_start[t + 1]; ++e) {
        const int g = b.tile_gauss[e];
        const double dx = st.mean2d[2 * g] - (x + 0.5), dy = st.mean2d[2 * g + 1] - (y + 0.5);
        const float* c = &st.conic[3 * g];
        const double a =
            std::min(0.99, st.opacity[g] * std::exp(-0.5 * (c[0] * dx * dx + c[2] * dy * dy) - c[1] * dx * dy));
        if (a < 1.0 / 255) continue;
        if (T * (1 - a) < 1e-4) break;
        T *= 1 - a;
        total += 1;
      }
    }
  return total / (double(b.width) * b.height);
}

void BM_RasterizeForward(benchmark::State& state) {
  const bench::OmpThreads threads(state, 0);
  Stages& st = stages();
  state.counters["composited/px"] = composited_per_pixel(st);
  for (auto _ : state) rasterize_forward(st.in, st.bins, st.ws, st.out);
  // average (tile-local index + 1) of the last contributor per pixel: how deep into its tile list a pixel goes
  double s = 0;
  for (int32_t v : st.last) s += v;
  state.counters["depth/px"] = s / st.last.size();
}

void BM_RasterizeBackward(benchmark::State& state) {
  const bench::OmpThreads threads(state, 0);
  Stages& st = stages();
  rasterize_forward(st.in, st.bins, st.ws, st.out);
  const int n = scene().n;
  std::vector<float> drgb(st.rgb.size(), 0.1f), gm(2 * n), gc(3 * n), go(n), gcol(3 * n), gd(n);
  for (size_t i = 0; i < drgb.size(); ++i) drgb[i] = 0.01f * float(i % 7) - 0.03f;
  RasterGrads<float> g;
  g.d_rgb = drgb.data();
  g.mean2d = gm.data(), g.conic = gc.data(), g.opacity = go.data(), g.color = gcol.data(), g.depth = gd.data();
  for (auto _ : state) rasterize_backward(st.in, st.bins, st.ws, st.finalT.data(), st.last.data(), g);
}

void BM_RenderForward(benchmark::State& state) {
  const bench::OmpThreads threads(state, 0);
  BenchScene& s = scene();
  GaussianRenderer r;
  RenderOutputs out;
  RenderSettings rs = s.rs;
  rs.want_depth = false;
  for (auto _ : state) r.forward(s.cam, s.g, rs, out);
  state.counters["visible"] = out.num_visible;
}

// RGB forward + backward of the whole renderer (projection, SH, binning, rasterize, and all backward stages).
void BM_RenderForwardBackward(benchmark::State& state) {
  const bench::OmpThreads threads(state, 0);
  BenchScene& s = scene();
  GaussianRenderer r;
  RenderOutputs out;
  GaussianGrads grads;
  RenderSettings rs = s.rs;
  rs.want_depth = false;
  std::vector<float> drgb(size_t(s.cam.width) * s.cam.height * 3);
  for (size_t i = 0; i < drgb.size(); ++i) drgb[i] = 0.01f * float(i % 7) - 0.03f;
  OutputGrads d;
  d.rgb = drgb.data();
  for (auto _ : state) {
    r.forward(s.cam, s.g, rs, out);
    r.backward(d, grads);
  }
}

}  // namespace

BENCHMARK(BM_Project)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ShForward)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_ShBackward)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_Binning)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RasterizeForward)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RasterizeBackward)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RenderForward)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_RenderForwardBackward)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();

BENCHMARK_MAIN();
