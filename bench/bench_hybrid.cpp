// One hybrid training step against one plain RGB step on the same scene, so the ratio asked of the hybrid method
// (<= 2x the RGB step) is read off one run. Scene: bench_hybrid_scene.h at 320x240 (30k Gaussians, SH degree 3,
// K = 8 objects + background present in each view, D = 512). Two hybrid steps:
// - BM_HybridStep: the object terms (paper eq. 15 without its semantic term: photometric + object-conditioned
//   appearance + BRO, with Observation Fusion and Adam on q's view logits). The scene's data has no SCL classes,
//   so the language term does not run. Exact (objects_per_step 0) and with the objects-per-step approximation (4
//   and 2 of the 9 present objects; hybrid/config.h), dense and sparse object channels.
// - BM_FullStep: the whole of eq. 15 with `hgs train`'s default config (bench::with_scl: every view's SCL classes
//   set, so also SCL's pixel-weight channels, the pooled predictions and Adam on f, D = 512). On this box the
//   associations are one-hot and every Gaussian has one object entry, so the method does less work than on a
//   capture (docs/performance.md, session twelve): bench/train_steps.sh times `hgs train` on a synthetic capture.
// Densification off; the observation table is rebuilt every R = 100 steps as in training. Every timing runs at
// each thread count of HGS_BENCH_THREADS (bench_threads.h; default 1, 2).
// The steps report the mean time of each part of the step as counters (ms_forward, ms_method_loss, ...; the
// hybrid steps also ms_method_loss_objects / _semantic). Also times the parts of a hybrid step separately
// (fusion, object channels, SCL pooling, the object losses with and without boxes) for profiling, and measures
// the peak memory of a 300k-Gaussian hybrid step (BM_HybridStepMemory300k, object terms only, run alone;
// bench_scale has the full-resolution cases).
//   build/bench_hybrid --benchmark_repetitions=5 --benchmark_report_aggregates_only=true
#include <benchmark/benchmark.h>

#include <map>

#include <cmath>
#include <random>

#include "bench_hybrid_scene.h"
#include "bench_scene.h"
#include "bench_threads.h"
#include "core/process.h"
#include "hybrid/fusion.h"
#include "hybrid/method.h"
#include "hybrid/object_channels.h"
#include "hybrid/object_losses.h"
#include "hybrid/scl.h"
#include "model/gaussian_model.h"
#include "model/render_inputs.h"
#include "render/renderer.h"
#include "train/ssim.h"
#include "train/trainer.h"

using namespace hgs;

namespace {

using bench::bench_model;
using bench::kH;
using bench::kN;
using bench::kW;
using bench::kD;
using bench::kK;
using bench::kViews;
using Setup = bench::HybridScene;

Setup& setup() {
  static Setup s;
  return s;
}

train::TrainConfig bench_config() {
  train::TrainConfig cfg;
  cfg.densify = false;
  cfg.sh_increase_every = 0;  // full SH degree 3 from the first step
  cfg.iters = 1000000;
  return cfg;
}

// Mean wall time of each part of the step (ms) as counters, so a run shows where the time goes.
struct PartTimes {
  train::StepTimes sum;
  double app = 0, sem = 0;
  std::map<std::string, double> phases;  // the object losses' phases and the buffers around them (method stats)
  long n = 0;
  void add(const train::StepInfo& info) {
    train::StepTimes::each([&](const char*, double train::StepTimes::*m) { sum.*m += info.times.*m; });
    ++n;
  }
  void report(benchmark::State& st) const {
    if (n == 0) return;
    train::StepTimes::each(
        [&](const char* name, double train::StepTimes::*m) { st.counters[std::string("ms_") + name] = sum.*m / n; });
    if (app > 0 || sem > 0) {
      st.counters["ms_method_loss_objects"] = app / n;
      st.counters["ms_method_loss_semantic"] = sem / n;
      for (const auto& [k, v] : phases) st.counters["ms_method_loss_" + k.substr(3)] = v / n;
    }
  }
};

void BM_RgbStep(benchmark::State& st) {
  const bench::OmpThreads threads(st, 0);
  auto& s = setup();
  train::Trainer trainer(bench_config(), s.model, s.views, 5.f);
  for (int i = 0; i < 3; ++i) trainer.step();
  PartTimes parts;
  for (auto _ : st) parts.add(trainer.step());
  parts.report(st);
}

// The hybrid step on data d with config hc, with its parts (the method's own timers beside train::StepTimes').
void hybrid_step(benchmark::State& st, const hybrid::HybridConfig& hc, const hybrid::HybridData& d) {
  auto& s = setup();
  train::Trainer trainer(bench_config(), s.model, s.views, 5.f,
                         std::make_unique<hybrid::HybridMethod>(hc, d, bench_config().seed));
  for (int i = 0; i < 3; ++i) trainer.step();
  double loss = 0;
  PartTimes parts;
  for (auto _ : st) {
    const train::StepInfo info = trainer.step();
    loss = info.total;
    parts.add(info);
    const train::MethodStats ms = trainer.method().stats();
    parts.app += ms.value("ms_app");
    parts.sem += ms.value("ms_sem");
    for (const char* k : {"ms_app_boxes", "ms_app_pieces", "ms_app_finish", "ms_app_scatter", "ms_buffers"})
      parts.phases[k] += ms.value(k);
  }
  st.counters["loss"] = loss;
  if (!std::isfinite(loss)) st.SkipWithError("the hybrid step's loss is not finite");  // timing NaNs is no figure
  parts.report(st);
}

// The hybrid method's object terms (the scene's data has no SCL classes: no language term).
// Args: HybridConfig::objects_per_step (0 = every present object, the exact eqs. 6 and 14) and
// HybridConfig::sparse_objects (0 = dense object channels, 1 = base render + sparse channel groups; both exact).
void BM_HybridStep(benchmark::State& st) {
  const bench::OmpThreads threads(st, 2);
  hybrid::HybridConfig hc;
  hc.objects_per_step = static_cast<int>(st.range(0));
  hc.sparse_objects = st.range(1) != 0;
  hybrid_step(st, hc, setup().data);
}

// The full method as `hgs train` runs it and the paper times it: the object terms and the language term (SCL,
// eqs. 9-10, D = 512: the pixel-weight channels, the pooled predictions, f's row updates), default config.
void BM_FullStep(benchmark::State& st) {
  const bench::OmpThreads threads(st, 0);
  const hybrid::HybridConfig hc;
  static const hybrid::HybridData data = bench::with_scl(setup().data, hc);
  hybrid_step(st, hc, data);
}

// Memory: the same step with 300k Gaussians (scales / 10^(1/3) so the box is covered alike), D = 512, with
// densification every other step. Reports
// the process's peak resident set size; run it alone so the other benchmarks do not count:
//   build/bench_hybrid --benchmark_filter=Memory300k
void BM_HybridStepMemory300k(benchmark::State& st) {
  const int n = 300000;
  GaussianModel m = bench_model(99, n, 1.f / std::cbrt(10.f));
  auto& s = setup();
  // Densification every other step (row gathers of the model and the Adam moments are the transient peak).
  train::TrainConfig cfg = bench_config();
  cfg.densify = true;
  cfg.densify_from = 1;
  cfg.densify_every = 2;
  train::Trainer trainer(cfg, std::move(m), s.views, 5.f,
                         std::make_unique<hybrid::HybridMethod>(hybrid::HybridConfig{}, s.data, cfg.seed));
  for (int i = 0; i < 2; ++i) trainer.step();
  for (auto _ : st) benchmark::DoNotOptimize(trainer.step().total);
  st.counters["gaussians"] = trainer.model().n;
  st.counters["peak_rss_MB"] = peak_rss_mb();
}

// Parts of the step, for profiling.
void BM_Fuse(benchmark::State& st) {
  const bench::OmpThreads threads(st, 0);
  auto& s = setup();
  hybrid::ObservationTable tab;
  hybrid::observe(s.model.mean.data(), kN, s.data.masks, tab);
  std::vector<float> w(kViews, 1.f / kViews), q(size_t(kN) * (kK + 1)), sbuf(q.size());
  std::vector<uint8_t> valid(kN);
  hybrid::FusionParams p{kK + 1, 0.1, 1e-6};
  for (auto _ : st) hybrid::fuse(tab, w.data(), p, q.data(), sbuf.data(), valid.data());
}

// Eqs. 4-5 and their backward at the size of a real capture: 55k Gaussians, U = 48 views, each Gaussian observed
// in about 70 % of them, mostly as one label (10 % of the observations another, 20 % background). Arg 0: fuse;
// 1: fuse + fuse_backward.
void BM_FuseViews(benchmark::State& st) {
  const bench::OmpThreads threads(st, 1);
  const int n = 55000, U = 48, L = kK + 1;
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> R(0, 1);
  std::uniform_int_distribution<int> lab(1, kK);
  hybrid::ObservationTable tab;
  tab.n = n;
  tab.num_views = U;
  tab.label.resize(size_t(n) * U);
  for (int i = 0; i < n; ++i) {
    const int own = lab(rng);
    for (int u = 0; u < U; ++u) {
      const float r = R(rng);
      tab.label[size_t(i) * U + u] = r < 0.3f ? hybrid::kNoObservation : r < 0.5f ? 0 : r < 0.57f ? lab(rng) : own;
    }
  }
  std::vector<float> w(U), q(size_t(n) * L), sbuf(q.size()), dq(q.size()), dw(U);
  for (int u = 0; u < U; ++u) w[u] = (0.5f + R(rng)) / U;
  for (auto& x : dq) x = R(rng) - 0.5f;
  std::vector<uint8_t> valid(n);
  std::vector<float> z(n), den(n);
  hybrid::FusionParams p{L, 0.1, 1e-6, 0.5};
  for (auto _ : st) {  // as ObjectAssociation runs them: z and the normalisers written by fuse
    hybrid::fuse(tab, w.data(), p, q.data(), sbuf.data(), valid.data(), z.data(), den.data());
    if (st.range(0))
      hybrid::fuse_backward(tab, w.data(), p, sbuf.data(), q.data(), valid.data(), dq.data(), dw.data(), den.data());
  }
}

void BM_ObjectChannels(benchmark::State& st) {
  const bench::OmpThreads threads(st, 0);
  const int L = kK + 1;
  const hybrid::ObjectLayout lay{L, 0};
  std::vector<float> q(size_t(kN) * L, 0.1f), col(size_t(kN) * 3, 0.5f), extra(size_t(kN) * lay.total());
  std::vector<int> objs(L);
  for (int l = 0; l < L; ++l) objs[l] = l;
  for (auto _ : st) hybrid::object_channels(kN, L, lay, objs.data(), q.data(), col.data(), extra.data());
}

void BM_PooledPrediction(benchmark::State& st) {
  const bench::OmpThreads threads(st, 0);
  const int L = kK + 1;
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> U(0, 1);
  std::vector<float> q(size_t(kN) * L), f(size_t(kN) * kD), a(size_t(kN) * kK), mass(kK, 1000.f), P(size_t(kK) * kD);
  for (auto& x : q) x = U(rng);
  for (auto& x : f) x = U(rng);
  for (auto& x : a) x = U(rng) < 0.2f ? U(rng) : 0.f;
  std::vector<int> objs(kK);
  for (int k = 0; k < kK; ++k) objs[k] = k + 1;
  for (auto _ : st)
    hybrid::pooled_prediction(kN, kD, L, kK, q.data(), f.data(), a.data(), objs.data(), mass.data(), 1e-6f, P.data());
}

// SCL's pooled predictions as the trainer runs them (half-precision f, as on the room: 300k Gaussians, D = 512,
// J = 18 anchors, 58 % of the Gaussians touching a mask, one or two of its maps each): arg 0 `half`: 0 = each row
// widened into a float copy by ExtraGroup::row and then added (before 2026-12-07), 1 = pooled_prediction_half,
// converted in registers as it is added (the same bits).
void BM_PooledPredictionHalf(benchmark::State& st) {
  const bench::OmpThreads threads(st, 1);
  const int n = 300000, D = 512, J = 18, L = 14;
  static ExtraGroup f;
  static std::vector<float> q, a;
  if (f.half.empty()) {
    std::mt19937 rng(2);
    f.dim = D;
    f.f16 = true;
    f.half.resize(size_t(n) * D);
    for (auto& h : f.half) h = uint16_t(0x3000 + rng() % 0x0c00);  // values in [0.125, 1)
    q.resize(size_t(n) * L);
    for (auto& x : q) x = float(rng() % 1000 + 1) / 1000.f;
    a.assign(size_t(n) * J, 0.f);
    for (int i = 0; i < n; ++i)
      if (rng() % 100 < 58) {
        a[size_t(i) * J + rng() % J] = 1.f;
        if (rng() % 3 == 0) a[size_t(i) * J + rng() % J] = 0.5f;
      }
  }
  std::vector<int> objs(J);
  for (int j = 0; j < J; ++j) objs[j] = j % L;
  std::vector<float> mass(J, 1000.f), P(size_t(J) * D);
  const bool half = st.range(0) != 0;
  for (auto _ : st) {
    if (half) {
      hybrid::pooled_prediction_half(n, D, L, J, q.data(), f.half.data(), a.data(), objs.data(), mass.data(), 1e-6f,
                                     P.data());
    } else {
      hybrid::pooled_prediction_rows(
          n, D, L, J, q.data(),
          [&](long i, float* buf) -> const float* {
            f.row(size_t(i), buf);
            return buf;
          },
          a.data(), objs.data(), mass.data(), 1e-6f, P.data());
    }
    benchmark::DoNotOptimize(P.data());
  }
}

// Render forward + backward with 4 channels per present object (9 with the background; the opacity channels
// forward-only) and the 8 pixel-weight sums of the SCL anchors (arg 1), or the plain RGB render (arg 0).
void BM_RenderObjects(benchmark::State& st) {
  const bench::OmpThreads threads(st, 1);
  auto& s = setup();
  // 0: RGB only; 1: 4 dense channels per label + the SCL pixel weights; 2: the sparse layout (4 base channels,
  // one group of 4 per Gaussian, object_groups.h) + the pixel weights; 3: the pixel weights alone; 4: the 4 base
  // channels alone; 5: the groups alone; 6: the pixel weights alone without their gradient (the default training
  // step's SCL: the weight sums are forward-only unless HybridConfig::sem_geometry). Modes 1-3 pass the sums'
  // gradient.
  const int mode = static_cast<int>(st.range(0));
  const int L = kK + 1, C = mode == 1 ? 4 * L : (mode == 2 || mode == 4) ? 4 : 0;
  const int J = ((mode >= 1 && mode <= 3) || mode == 6) ? kK : 0, G = (mode == 2 || mode == 5) ? L : 0;
  render::GaussianRenderer r;
  render::RenderOutputs out;
  render::GaussianGrads g;
  render::GaussianInputs in = render_inputs(s.model);
  std::vector<float> extra(size_t(kN) * C, 0.1f), pw(size_t(kW) * kH * J), d_rgb(size_t(kW) * kH * 3, 1e-3f),
      d_extra(size_t(kW) * kH * C, 1e-3f), d_ws(size_t(kN) * J, 1e-3f), gval(size_t(kN) * 4, 0.2f),
      d_groups(size_t(kW) * kH * 3 * G, 1e-3f);
  std::vector<int> gptr(size_t(kN) + 1), gid(kN);
  for (int i = 0; i <= kN; ++i) gptr[i] = i;
  for (int i = 0; i < kN; ++i) gid[i] = i % L;
  const LabelMap& lab = s.data.masks[0].labels;
  for (size_t p = 0; p < lab.v.size(); ++p)
    for (int j = 0; j < J; ++j) pw[size_t(j) * lab.v.size() + p] = lab.v[p] == j + 1;  // planar [J, H, W]
  render::Channels ch;
  ch.extra = extra.data();
  ch.num_extra = C;
  if (G) {
    ch.num_groups = G;
    ch.group_width = 4;
    ch.group_ptr = gptr.data();
    ch.group_id = gid.data();
    ch.group_val = gval.data();
  }
  render::RenderSettings rs;
  rs.want_depth = false;
  rs.pixel_weights = J ? pw.data() : nullptr;
  rs.num_pixel_weights = J;
  render::OutputGrads dout;
  dout.rgb = d_rgb.data();
  dout.extra = C ? d_extra.data() : nullptr;
  dout.extra_grad_channels = mode == 1 ? 3 * L : C == 4 ? 3 : -1;  // the opacities are forward-only
  dout.weight_sums = J && mode != 6 ? d_ws.data() : nullptr;
  if (G) {
    dout.groups = d_groups.data();
    dout.group_row = 3 * G;
    dout.group_stride = 3;
    dout.group_grad_channels = 3;
  }
  render::ProjectedGrads pg;
  for (auto _ : st) {
    r.preprocess(s.views[0].cam, in);
    r.composite(ch, rs, out);
    r.composite_backward(dout, pg);
    r.preprocess_backward(pg, g);
  }
}

// SSIM forward + backward of the 9 object images of a view as one 27-channel image (arg 1) or 9 3-channel ones.
void BM_ObjectSsim(benchmark::State& st) {
  const bench::OmpThreads threads(st, 1);
  const int L = kK + 1;
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> U(0, 1);
  std::vector<float> a(size_t(kW) * kH * 3 * L), b(a.size()), g(a.size());
  for (auto& x : a) x = U(rng);
  for (auto& x : b) x = U(rng);
  train::SsimWorkspace<float> ws;
  for (auto _ : st) {
    if (st.range(0)) {
      benchmark::DoNotOptimize(train::ssim(a.data(), b.data(), kH, kW, 3 * L, g.data(), ws));
    } else {
      const size_t img = size_t(kW) * kH * 3;
      for (int l = 0; l < L; ++l)
        benchmark::DoNotOptimize(
            train::ssim(a.data() + l * img, b.data() + l * img, kH, kW, 3, g.data() + l * img, ws));
    }
  }
}

// Eqs. 6 and 14 for the 9 objects of view 0 (hybrid/object_losses.h) on a real composite of the object channels
// with the base channels (q fused from the bench masks, the renderer's SH colours), with boxes (arg 1) or every
// object over the whole image (arg 0); both give the same values and gradients. The renders in and the gradients
// out in the training step's layout (object_groups.h).
void BM_ObjectLosses(benchmark::State& st) {
  const bench::OmpThreads threads(st, 1);
  auto& s = setup();
  const int L = kK + 1;
  hybrid::ObservationTable tab;
  hybrid::observe(s.model.mean.data(), kN, s.data.masks, tab);
  std::vector<float> w(kViews, 1.f / kViews), q(size_t(kN) * L), sbuf(q.size());
  std::vector<uint8_t> valid(kN);
  hybrid::fuse(tab, w.data(), hybrid::FusionParams{L, 0.1, 1e-6}, q.data(), sbuf.data(), valid.data());
  const hybrid::ObjectLayout lay{L, 0, true};
  std::vector<int> objs(L);
  for (int l = 0; l < L; ++l) objs[l] = l;
  render::GaussianRenderer r;
  const render::GaussianInputs in = render_inputs(s.model);
  r.preprocess(s.views[0].cam, in);
  std::vector<float> ch(size_t(kN) * lay.total());
  hybrid::object_channels(kN, L, lay, objs.data(), q.data(), r.projected().colors, ch.data());
  render::RenderSettings rs;
  rs.want_depth = false;
  render::RenderOutputs out;
  render::Channels channels;
  channels.extra = ch.data();
  channels.num_extra = lay.total();
  r.composite(channels, rs, out);
  // The renders as training reads them (the base render's channels and each object's difference from them, one
  // plane per object) and the gradients as it writes them (the objects' colours [H, W, 3 J] and their sum [H, W, 3]).
  const long HW = long(kW) * kH;
  const int C = lay.total();
  std::vector<float> dense(size_t(HW) * 4), groups(size_t(HW) * 4 * L);
  for (long p = 0; p < HW; ++p) {
    const float* e = &out.extra[size_t(p) * C];
    for (int c = 0; c < 4; ++c) dense[size_t(p) * 4 + c] = e[c < 3 ? lay.base_color() + c : lay.base_opacity()];
    for (int j = 0; j < L; ++j)
      for (int c = 0; c < 4; ++c)
        groups[(size_t(j) * HW + p) * 4 + c] = e[c < 3 ? lay.color(j) + c : lay.opacity(j)] - dense[size_t(p) * 4 + c];
  }
  const hybrid::ObjectRenders renders = hybrid::ObjectRenders::sparse(dense.data(), 4, 3, groups.data(), L, HW);
  hybrid::ObjectLosses losses(hybrid::HybridConfig{}, {.boxes = st.range(0) != 0});
  std::vector<float> d(size_t(HW) * 3 * L), sum(size_t(HW) * 3);
  for (auto _ : st)
    benchmark::DoNotOptimize(
        losses(s.views[0].image, s.data.masks[0].labels, renders, objs, {d.data(), 3L * L, sum.data(), 3}).app);
}

}  // namespace

BENCHMARK(BM_ObjectLosses)
    ->ArgNames({"boxes", "threads"})
    ->ArgsProduct({{0, 1}, bench::thread_counts()})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_RenderObjects)
    ->ArgNames({"objects", "threads"})
    ->ArgsProduct({{0, 1, 2, 3, 4, 5, 6}, bench::thread_counts()})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_ObjectSsim)
    ->ArgNames({"one_image", "threads"})
    ->ArgsProduct({{0, 1}, bench::thread_counts()})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_RgbStep)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_HybridStep)
    ->ArgNames({"objects_per_step", "sparse", "threads"})
    ->ArgsProduct({{0, 4, 2}, {0, 1}, bench::thread_counts()})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_FullStep)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_HybridStepMemory300k)->Unit(benchmark::kMillisecond)->UseRealTime()->Iterations(3);
BENCHMARK(BM_Fuse)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_FuseViews)
    ->ArgNames({"backward", "threads"})
    ->ArgsProduct({{0, 1}, bench::thread_counts()})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK(BM_ObjectChannels)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_PooledPrediction)->Apply(bench::at_each_thread_count)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_PooledPredictionHalf)
    ->ArgNames({"half", "threads"})
    ->ArgsProduct({{0, 1}, bench::thread_counts()})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime();
BENCHMARK_MAIN();
