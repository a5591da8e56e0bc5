// Benchmarks of the training glue at 320x240 (times in ms, wall clock, at each thread count of HGS_BENCH_THREADS,
// default 1 and 2): SSIM forward, SSIM forward+backward, the full photometric loss (L1 + D-SSIM with gradient), one
// Adam update of 30k Gaussians with SH degree 3 (59 floats each), and one full RGB training step (render forward, loss,
// backward, Adam) through train::Trainer with densification off. Scene: camera at the origin looking down +z
// (fx = fy = 300), 30k Gaussians uniform in the box [-2.5, 2.5] x [-1.9, 1.9] x [3, 7], log-uniform scales
// in [0.01, 0.06], random rotations, opacity U[0.05, 0.95], SH DC N(0, 0.5), higher N(0, 0.1); the target
// image is the render of the same scene with the DC colours perturbed by N(0, 0.3), so gradients are real.
//   build-<you>/bench_train --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <cmath>
#include <random>

#include "bench_scene.h"
#include "bench_threads.h"
#include "model/gaussian_model.h"
#include "render/renderer.h"
#include "train/adam.h"
#include "train/loss.h"
#include "train/ssim.h"
#include "train/trainer.h"

using namespace hgs;

namespace {

using bench::bench_camera;
using bench::bench_model;
using bench::kH;
using bench::kN;
using bench::kW;

// Ground truth from the unperturbed model; the trained model has its DC colours perturbed.
struct BenchData {
  GaussianModel model;
  Image target;
  std::vector<float> a, b;  // two 320x240x3 images for the loss benchmarks
  BenchData() {
    GaussianModel gt = bench_model(1234);
    render::GaussianRenderer r;
    render::RenderOutputs out;
    render::GaussianInputs in;
    in.n = gt.n;
    in.mean = gt.mean.data();
    in.log_scale = gt.log_scale.data();
    in.quat = gt.quat.data();
    in.opacity_logit = gt.opacity_logit.data();
    in.sh = gt.sh.data();
    in.sh_stride = 16;
    in.sh_degree = 3;
    r.forward(bench_camera(), in, {}, out);
    target = Image(kW, kH, 3);
    target.px = out.rgb;
    model = gt;
    std::mt19937 rng(7);
    std::normal_distribution<float> N(0, 0.3f);
    for (int i = 0; i < kN; ++i)
      for (int c = 0; c < 3; ++c) model.sh[i * 48 + c] += N(rng);
    in.sh = model.sh.data();
    r.forward(bench_camera(), in, {}, out);
    a = out.rgb;
    b = target.px;
  }
};

BenchData& data() {
  static BenchData d;
  return d;
}

void BM_SsimForward(benchmark::State& st) {
  const bench::OmpThreads threads(st, 0);
  auto& d = data();
  train::SsimWorkspace<float> ws;
  for (auto _ : st) benchmark::DoNotOptimize(train::ssim(d.a.data(), d.b.data(), kH, kW, 3, (float*)nullptr, ws));
}

void BM_SsimForwardBackward(benchmark::State& st) {
  const bench::OmpThreads threads(st, 0);
  auto& d = data();
  train::SsimWorkspace<float> ws;
  std::vector<float> g(d.a.size());
  for (auto _ : st) benchmark::DoNotOptimize(train::ssim(d.a.data(), d.b.data(), kH, kW, 3, g.data(), ws));
}

// SSIM forward + backward of a random 3-channel image of 76,800 pixels at width arg (320: the bench image's
// shape; 40: a narrow crop, many rows and few columns, as the hybrid method's object losses score).
void BM_SsimWidth(benchmark::State& st) {
  const bench::OmpThreads threads(st, 1);
  const int W = static_cast<int>(st.range(0)), H = 76800 / W;
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> U(0, 1);
  std::vector<float> a(size_t(W) * H * 3), b(a.size()), g(a.size());
  for (auto& x : a) x = U(rng);
  for (auto& x : b) x = U(rng);
  train::SsimWorkspace<float> ws;
  for (auto _ : st) benchmark::DoNotOptimize(train::ssim(a.data(), b.data(), H, W, 3, g.data(), ws));
}

void BM_PhotometricLoss(benchmark::State& st) {
  const bench::OmpThreads threads(st, 0);
  auto& d = data();
  train::PhotometricLoss loss;
  std::vector<float> g(d.a.size());
  for (auto _ : st) benchmark::DoNotOptimize(loss(d.a.data(), d.b.data(), kH, kW, g.data()).total);
}

void BM_AdamUpdate30k(benchmark::State& st) {
  const bench::OmpThreads threads(st, 0);
  GaussianModel m = data().model;
  train::Adam adam;
  std::vector<std::vector<float>> grads;
  std::mt19937 rng(3);
  std::normal_distribution<float> N(0, 1e-3f);
  for (auto& f : m.fields()) {
    train::AdamParam& p = adam.add(f.name, f.dim, m.n, 1e-3f);
    if (f.name == "sh")
      for (int c = 0; c < 3; ++c) p.lr[c] = 2.5e-3f;
    grads.emplace_back(f.data->size());
    for (auto& g : grads.back()) g = N(rng);
  }
  for (auto _ : st) {
    auto fields = m.fields();
    for (size_t k = 0; k < fields.size(); ++k)
      adam.update(adam.params[k], fields[k].data->data(), grads[k].data(), m.n);
  }
}

// The language embeddings' row update as the full method runs it (SemanticPass::update): D = 512, values in IEEE
// half, bfloat16 moments, rows with a gradient in runs of 4 of every 7 (57 %: the room at 1000x700 gives 175k of
// its 300k rows one, clustered by index). Arg 0:
// rows; at 2k rows (6 MB of values and moments) the rows stay in the caches, at 300k (922 MB) every update
// streams them from memory: the two times say whether the update is bound by arithmetic or by bandwidth. Arg 1:
// the AVX-512 kernel (1, the default where the CPU has it) or the AVX2 one (0); the same bits.
void BM_AdamRowsHalf(benchmark::State& st) {
  const bench::OmpThreads threads(st, 2);
  const bool was = train::adam_avx512();
  if (!train::set_adam_avx512(st.range(1) != 0) && st.range(1)) {
    st.SkipWithError("no AVX-512 on this CPU");
    return;
  }
  const int n = int(st.range(0)), D = 512;
  train::Adam adam;
  train::AdamParam& p = adam.add("f", D, n, 2.5e-3f, true);
  std::vector<uint16_t> x(size_t(n) * D, 0x3800);  // 0.5
  std::vector<float> g0(D);
  std::mt19937 rng(3);
  std::normal_distribution<float> N(0, 1e-3f);
  for (auto& v : g0) v = N(rng);
  auto rows = [&](long i, float* g) {
    if (i % 7 >= 4) return false;
    std::copy(g0.begin(), g0.end(), g);
    return true;
  };
  adam.update_rows(p, x.data(), n, rows);  // touch every page once
  for (auto _ : st) adam.update_rows(p, x.data(), n, rows);
  st.counters["rows_updated"] = double(n / 7 * 4 + std::min(n % 7, 4));
  train::set_adam_avx512(was);
}

void BM_TrainStep(benchmark::State& st) {
  const bench::OmpThreads threads(st, 0);
  auto& d = data();
  train::TrainConfig cfg;
  cfg.densify = false;
  cfg.sh_increase_every = 0;  // full SH degree 3 from the first step
  cfg.iters = 1000000;
  std::vector<train::TrainView> views(1);
  views[0].name = "bench";
  views[0].cam = bench_camera();
  views[0].image = d.target;
  train::Trainer trainer(cfg, d.model, views, 5.f);
  for (int i = 0; i < 3; ++i) trainer.step();  // warm the buffers
  double loss = 0;
  for (auto _ : st) loss = trainer.step().loss.total;
  st.counters["loss"] = loss;
}

}  // namespace

BENCHMARK(BM_SsimForward)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_SsimForwardBackward)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_SsimWidth)
    ->ArgNames({"width", "threads"})
    ->ArgsProduct({{40, 160, 320, 640}, bench::thread_counts()})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_PhotometricLoss)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_AdamUpdate30k)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_AdamRowsHalf)
    ->ArgNames({"rows", "avx512", "threads"})
    ->ArgsProduct({{2048, 300000}, {1, 0}, bench::thread_counts()})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_TrainStep)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK_MAIN();
