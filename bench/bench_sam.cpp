// SAM speed on this machine at ViT-B shapes (sam-vit-base: hidden 768 x 12 layers, 12 heads, window 14, global
// layers 2, 5, 8, 11, 1024 px, patch 16; neck / decoder 256, 2 decoder layers, 8 heads; random weights built
// here, no file needed): the image embedding at 1024x1024, the mask decoder on a batch of 64 single-point
// prompts, a whole automatic-mask image (32 x 32 grid, segment-anything's defaults, embedding included), the
// mask post-processing with every mask kept, and
// a plain sgemm of the ViT MLP's shape for the attainable FLOP rate. Counters: FLOPS (from the model's
// multiply-adds, to compare with the sgemm's), peak RSS of the process (MB). Every benchmark runs at each thread
// count of HGS_BENCH_THREADS (default "1,2"; OpenMP, the blocking pool and OpenBLAS all set to it), so one run
// shows how each part scales (bench/run_multicore.sh runs it at 1-16 threads).
//   ./build/bench_sam --benchmark_min_time=1
//   HGS_BENCH_THREADS=1,2,4,8,16 ./build/bench_sam --benchmark_filter='f32'
#include <benchmark/benchmark.h>
#include <cblas.h>
#include <omp.h>

#include <cmath>
#include <cstdlib>
#include <random>
#include <sstream>

#include "bench_threads.h"
#include "clip/model.h"
#include "core/process.h"
#include "nn/openblas_env.h"
#include "nn/thread_pool.h"
#include "sam/amg.h"
#include "sam/model.h"

using namespace hgs;
using namespace hgs::sam;

HGS_OPENBLAS_PREINIT();
// OpenBLAS's kernels in the run's header (nn/openblas_env.h: a generic one makes every product 5-6x slower).
const bool kOpenBlasContext = (benchmark::AddCustomContext("openblas_core", openblas_get_corename()), true);

namespace {

constexpr int kHidden = 768, kLayers = 12, kHeads = 12, kWindow = 14, kGrid = 64, kPatch = 16, kOut = 256;

std::vector<float> randn(size_t n, float scale, std::mt19937& rng) {
  std::normal_distribution<float> d(0.f, scale);
  std::vector<float> v(n);
  for (auto& x : v) x = d(rng);
  return v;
}

Linear lin(int out, int in, std::mt19937& rng) {
  return {in, out, randn(size_t(out) * in, 1.f / std::sqrt(float(in)), rng), randn(out, 0.02f, rng)};
}
LayerNorm ln(int c) { return {std::vector<float>(c, 1.f), std::vector<float>(c, 0.f)}; }
Attention attn(int c, int inner, std::mt19937& rng) {
  return {lin(inner, c, rng), lin(inner, c, rng), lin(inner, c, rng), lin(c, inner, rng)};
}
Mlp mlp(int in, int hidden, int out, std::mt19937& rng) {
  return {{lin(hidden, in, rng), lin(hidden, hidden, rng), lin(out, hidden, rng)}};
}
Upconv upconv(int in, int out, std::mt19937& rng) {
  return {in, out, randn(size_t(in) * 4 * out, 1.f / std::sqrt(float(in)), rng), randn(out, 0.02f, rng)};
}

const SamModel& vit_b(int bf16 = 0) {
  static SamModel models[2];
  static bool made[2] = {false, false};
  if (made[bf16]) return models[bf16];
  made[bf16] = true;
  SamModel& m = models[bf16];
  m = [] {
    std::mt19937 rng(1);
    SamModel s;
    VisionEncoder& v = s.vision;
    v.patch = kPatch, v.grid = kGrid, v.hidden = kHidden, v.heads = kHeads, v.out = kOut;
    v.patch_embed = lin(kHidden, 3 * kPatch * kPatch, rng);
    v.pos = randn(size_t(kGrid) * kGrid * kHidden, 0.02f, rng);
    const int hd = kHidden / kHeads;
    for (int i = 0; i < kLayers; ++i) {
      VitLayer l;
      l.window = (i % 3 == 2) ? 0 : kWindow;
      const int size = l.window ? l.window : kGrid;
      l.ln1 = l.ln2 = ln(kHidden);
      l.qkv = lin(3 * kHidden, kHidden, rng);
      l.proj = lin(kHidden, kHidden, rng);
      l.fc1 = lin(4 * kHidden, kHidden, rng);
      l.fc2 = lin(kHidden, 4 * kHidden, rng);
      l.rel_h = randn(size_t(2 * size - 1) * hd, 0.02f, rng);
      l.rel_w = randn(size_t(2 * size - 1) * hd, 0.02f, rng);
      v.layers.push_back(std::move(l));
    }
    v.neck1 = {kHidden, kOut, randn(size_t(kOut) * kHidden, 1.f / std::sqrt(float(kHidden)), rng),
               std::vector<float>(kOut, 0.f)};
    v.neck2 = {9 * kOut, kOut, randn(size_t(kOut) * 9 * kOut, 1.f / std::sqrt(9.f * kOut), rng),
               std::vector<float>(kOut, 0.f)};
    v.neck_ln1 = v.neck_ln2 = ln(kOut);
    PromptEncoder& p = s.prompt;
    p.gauss = randn(size_t(kOut), 1.f, rng);
    for (auto& e : p.point) e = randn(kOut, 1.f, rng);
    p.not_a_point = randn(kOut, 1.f, rng);
    p.no_mask = randn(kOut, 1.f, rng);
    MaskDecoder& d = s.decoder;
    d.heads = 8;
    d.tokens = 4;
    d.iou_token = randn(kOut, 1.f, rng);
    d.mask_tokens = randn(size_t(4) * kOut, 1.f, rng);
    for (int i = 0; i < 2; ++i) {
      TwoWayLayer l;
      l.self_attn = attn(kOut, kOut, rng);
      l.token_to_image = attn(kOut, kOut / 2, rng);
      l.image_to_token = attn(kOut, kOut / 2, rng);
      l.ln1 = l.ln2 = l.ln3 = l.ln4 = ln(kOut);
      l.mlp1 = lin(2048, kOut, rng);
      l.mlp2 = lin(kOut, 2048, rng);
      d.layers.push_back(std::move(l));
    }
    d.final_attn = attn(kOut, kOut / 2, rng);
    d.ln_final = ln(kOut);
    d.up1 = upconv(kOut, kOut / 4, rng);
    d.up_ln = ln(kOut / 4);
    d.up2 = upconv(kOut / 4, kOut / 8, rng);
    for (int i = 0; i < 4; ++i) d.hyper.push_back(mlp(kOut, kOut, kOut / 8, rng));
    d.iou_head = mlp(kOut, 256, 4, rng);
    return s;
  }();
  m.set_precision(bf16 ? clip::Precision::BF16 : clip::Precision::F32);
  return m;
}

// Benchmark argument 0 = float32, 1 = bfloat16 products; the label names the precision (and oneDNN's kernel).
void label(benchmark::State& state, int bf16) { state.SetLabel(bf16 ? "bf16 " + nn::bf16_kernel_name() : "f32"); }

// Argument 1: the thread count of OpenMP, the element-wise pool and OpenBLAS (nn::set_num_threads, what
// --threads sets) for the benchmark's lifetime.
class Threads {
 public:
  explicit Threads(const benchmark::State& st) : prev_(omp_get_max_threads()) { nn::set_num_threads(int(st.range(1))); }
  ~Threads() { nn::set_num_threads(prev_); }
  Threads(const Threads&) = delete;
  Threads& operator=(const Threads&) = delete;

 private:
  int prev_;
};

// precision x threads, named.
void precision_and_threads(benchmark::internal::Benchmark* b) {
  b->ArgNames({"bf16", "threads"});
  for (int p : {0, 1})
    for (int64_t t : bench::thread_counts()) b->Args({p, t});
}
void threads_only(benchmark::internal::Benchmark* b) {
  b->ArgNames({"n", "threads"});
  for (int64_t t : bench::thread_counts()) b->Args({4096, t});
}

// Multiply-add FLOPs (2 per MAC) of the image encoder.
double encoder_flops() {
  const double C = kHidden, N = double(kGrid) * kGrid;
  const int nw = (kGrid + kWindow - 1) / kWindow;
  const double M = double(nw) * nw * kWindow * kWindow;  // padded windowed tokens
  double f = 2 * N * C * 3 * kPatch * kPatch;
  for (int i = 0; i < kLayers; ++i) {
    const bool global = i % 3 == 2;
    const double t = global ? N : M, s2 = global ? N : double(kWindow) * kWindow, wins = global ? 1 : double(nw) * nw;
    f += 2 * t * C * 4 * C;                        // qkv, proj
    f += 4 * wins * s2 * s2 * C;                   // Q K^T and P V
    f += 2 * 2 * t * (2 * std::sqrt(s2) - 1) * C;  // relative-position tables
    f += 2 * N * C * 8 * C;                        // MLP
  }
  f += 2 * N * C * kOut + 2 * N * 9.0 * kOut * kOut;  // neck
  return f;
}

// FLOPs the decoder executes for B single-point prompts (Tt = 7 tokens: iou, 4 masks, point, padding), with
// the reassociated cross attentions of src/sam/decoder_attention.h; elementwise work not counted.
double decoder_flops(int B) {
  const double C = kOut, I = kOut / 2, N = double(kGrid) * kGrid, Tt = 7, R = 8 * Tt;
  const double shared = 3 * (2 * N * C * I);  // layer 0: token-to-image k, v; image-to-token q
  double per = 0;
  per += 2 * (2 * Tt * N * I);                            // layer 0 token-to-image scores and values
  per += 2 * N * Tt * I + 2 * N * R * C;                  // layer 0 image-to-token scores, values through out_proj
  per += 2 * (2 * R * N * C);                             // layer 1 token-to-image (few queries)
  per += 2 * N * C * I + 2 * N * Tt * I + 2 * N * R * C;  // layer 1 image-to-token
  per += 2 * (2 * R * N * C);                             // final token-to-image
  per += 2 * N * C * 4 * (C / 4) + 2 * 4 * N * (C / 4) * 4 * (C / 8);  // upscaling
  per += 2 * 4 * (C / 8) * 16 * N;                                     // mask dot products
  return shared + B * per;
}

void BM_ImageEmbedding1024(benchmark::State& state) {
  Threads threads(state);
  const SamModel& m = vit_b(int(state.range(0)));
  label(state, int(state.range(0)));
  std::mt19937 rng(2);
  auto x = randn(size_t(1024) * 1024 * 3, 1.f, rng);
  for (auto _ : state) benchmark::DoNotOptimize(m.encode(x.data()));
  state.counters["FLOPS"] = benchmark::Counter(encoder_flops(), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["peak_RSS_MB"] = peak_rss_mb();
}
BENCHMARK(BM_ImageEmbedding1024)
    ->Apply(precision_and_threads)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(2);

void BM_Decoder64Prompts(benchmark::State& state) {
  Threads threads(state);
  const SamModel& m = vit_b(int(state.range(0)));
  label(state, int(state.range(0)));
  std::mt19937 rng(3);
  ImageEmbedding e;
  e.grid = kGrid, e.channels = kOut, e.orig_h = 768, e.orig_w = 1024, e.input_h = 768, e.input_w = 1024;
  e.data = randn(size_t(kGrid) * kGrid * kOut, 1.f, rng);
  std::vector<float> sparse;
  std::uniform_real_distribution<float> U(0.f, 1000.f);
  for (int i = 0; i < 64; ++i) {
    Prompt p;
    p.points = {{U(rng), U(rng) * 0.75f}};
    p.labels = {1};
    auto s = m.encode_prompt(m.to_input(e, p));
    sparse.insert(sparse.end(), s.begin(), s.end());
  }
  // One batch first: each thread's work buffers are made on its first batch and kept (page faults otherwise
  // counted in the first timed batch of each thread count).
  benchmark::DoNotOptimize(m.decode(e.data.data(), sparse.data(), 64, 2));
  for (auto _ : state) benchmark::DoNotOptimize(m.decode(e.data.data(), sparse.data(), 64, 2));
  state.counters["FLOPS"] = benchmark::Counter(decoder_flops(64), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["peak_RSS_MB"] = peak_rss_mb();
}
BENCHMARK(BM_Decoder64Prompts)
    ->Apply(precision_and_threads)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(2);

// A 1024 x 768 image of uniform noise.
Image random_image(unsigned seed) {
  Image img(1024, 768, 3);
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> U(0.f, 1.f);
  for (auto& v : img.px) v = U(rng);
  return img;
}

// A whole automatic-mask image: embedding + 32 x 32 points in batches of 64, segment-anything's thresholds.
void BM_AutomaticMasksImage(benchmark::State& state) {
  Threads threads(state);
  const SamModel& m = vit_b(int(state.range(0)));
  label(state, int(state.range(0)));
  const Image img = random_image(4);
  size_t masks = 0;
  for (auto _ : state) {
    ImageEmbedding e = m.embed(img);
    masks = generate_masks(m, e, AmgOptions{}).size();
  }
  state.counters["masks"] = double(masks);
  state.counters["FLOPS"] =
      benchmark::Counter(encoder_flops() + 16 * decoder_flops(64), benchmark::Counter::kIsIterationInvariantRate);
  state.counters["peak_RSS_MB"] = peak_rss_mb();
}
BENCHMARK(BM_AutomaticMasksImage)
    ->Apply(precision_and_threads)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(1);

// The automatic mask generator's post-processing, which random weights otherwise never reach: every output of an
// 8 x 8 grid kept (thresholds off), so each of the 192 masks is resampled to full size, scored and boxed, then
// NMS, holes and islands under 100 pixels, NMS again; the embedding is made once outside the timing.
void BM_AutomaticMasksAllKept(benchmark::State& state) {
  Threads threads(state);
  const SamModel& m = vit_b(int(state.range(0)));
  label(state, int(state.range(0)));
  const Image img = random_image(6);
  const ImageEmbedding e = m.embed(img);
  AmgOptions o;
  o.points_per_side = 8;
  o.pred_iou_thresh = -1e30f;
  o.stability_score_thresh = -1e30f;
  o.box_nms_thresh = 1.1f;       // keeps every mask, so the count does not depend on the scores
  o.min_mask_region_area = 100;  // and the small-region clean-up of each
  size_t masks = 0;
  for (auto _ : state) masks = generate_masks(m, e, o).size();
  state.counters["masks"] = double(masks);
}
BENCHMARK(BM_AutomaticMasksAllKept)
    ->Apply(precision_and_threads)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->Iterations(2);

// The reference rate: one sgemm with the shape of the ViT-B MLP up-projection, [n, 768] x [768, 3072].
void BM_SgemmReference(benchmark::State& state) {
  Threads threads(state);
  const int n = int(state.range(0)), k = 768, o = 3072;
  std::mt19937 rng(5);
  auto a = randn(size_t(n) * k, 1.f, rng), b = randn(size_t(o) * k, 1.f, rng);
  std::vector<float> c(size_t(n) * o);
  for (auto _ : state) {
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, n, o, k, 1.f, a.data(), k, b.data(), k, 0.f, c.data(), o);
    benchmark::DoNotOptimize(c.data());
  }
  state.counters["FLOPS"] = benchmark::Counter(2.0 * n * k * o, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_SgemmReference)->Apply(threads_only)->Unit(benchmark::kMillisecond)->UseRealTime();

// The same product in bfloat16 (nn/gemm_bf16.h: the operands rounded beforehand, float32 accumulation).
void BM_Bf16GemmReference(benchmark::State& state) {
  Threads threads(state);
  const int n = int(state.range(0)), k = 768, o = 3072;
  std::mt19937 rng(5);
  auto a = nn::to_bf16(randn(size_t(n) * k, 1.f, rng)), b = nn::to_bf16(randn(size_t(o) * k, 1.f, rng));
  std::vector<float> c(size_t(n) * o);
  for (auto _ : state) {
    nn::gemm_bf16(n, o, k, a.data(), k, b.data(), k, true, 1.f, nullptr, 0.f, c.data(), o);
    benchmark::DoNotOptimize(c.data());
  }
  state.SetLabel(nn::bf16_kernel_name());
  state.counters["FLOPS"] = benchmark::Counter(2.0 * n * k * o, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_Bf16GemmReference)->Apply(threads_only)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
