// CLIP speed on this machine with a ViT-B/16-shaped model (random weights built here, no file needed):
// text embedding latency per phrase, dense and global image features at 224x224 and 448x448, and a plain
// OpenBLAS sgemm of the same shape as the ViT's MLP for the attainable FLOP rate. Each image benchmark
// reports its own FLOP rate ("FLOPS" counter) computed from the model's multiply-adds, to compare with sgemm.
//   ./build/bench_clip --benchmark_min_time=2
#include <benchmark/benchmark.h>
#include <cblas.h>

#include <random>

#include "clip/model.h"
#include "nn/openblas_env.h"

// OpenBLAS with the kernels chosen for this CPU, as in hgs (nn/openblas_env.h: on a CPU model the library does not
// know it would measure its SSE3 fallback, 5-6x slower).
HGS_OPENBLAS_PREINIT();

using namespace hgs::clip;

namespace {

std::vector<float> randn(size_t n, float scale, std::mt19937& rng) {
  std::normal_distribution<float> d(0.f, scale);
  std::vector<float> v(n);
  for (auto& x : v) x = d(rng);
  return v;
}

Transformer random_transformer(int width, int layers, int heads, std::mt19937& rng) {
  Transformer t;
  t.width = width;
  t.heads = heads;
  const float s = 1.f / std::sqrt(float(width));
  for (int l = 0; l < layers; ++l) {
    Block b;
    b.ln1 = b.ln2 = {std::vector<float>(width, 1.f), std::vector<float>(width, 0.f)};
    b.qkv = {width, 3 * width, randn(size_t(3) * width * width, s, rng), std::vector<float>(3 * width, 0.f)};
    b.out = {width, width, randn(size_t(width) * width, s, rng), std::vector<float>(width, 0.f)};
    b.fc = {width, 4 * width, randn(size_t(4) * width * width, s, rng), std::vector<float>(4 * width, 0.f)};
    b.proj = {4 * width, width, randn(size_t(4) * width * width, s / 2, rng), std::vector<float>(width, 0.f)};
    t.blocks.push_back(std::move(b));
  }
  return t;
}

// ViT-B/16 (vision width 768 x 12, text width 512 x 12, D 512), GELU like LAION's open_clip model.
const ClipModel& vit_b16() {
  static ClipModel m = [] {
    std::mt19937 rng(1);
    ClipModel c;
    c.act = Activation::GELU;
    c.embed_dim = 512;
    c.has_vision = c.has_text = true;
    VisionTower& v = c.vision;
    v.patch = 16;
    v.grid = 14;
    const int w = 768, kk = 3 * 16 * 16;
    v.patch_embed = {kk, w, randn(size_t(w) * kk, 1.f / std::sqrt(float(kk)), rng), std::vector<float>(w, 0.f)};
    v.cls = randn(w, 0.02f, rng);
    v.pos = randn(size_t(197) * w, 0.02f, rng);
    v.ln_pre = v.ln_post = {std::vector<float>(w, 1.f), std::vector<float>(w, 0.f)};
    v.proj = randn(size_t(w) * 512, 0.036f, rng);
    v.tr = random_transformer(w, 12, 12, rng);
    const Linear& qkv = v.tr.blocks.back().qkv;
    v.last_value = {w, w, std::vector<float>(qkv.w.begin() + size_t(2) * w * w, qkv.w.end()),
                    std::vector<float>(w, 0.f)};
    TextTower& t = c.text;
    t.context = 77;
    t.vocab = 49408;
    t.tok_emb = randn(size_t(49408) * 512, 0.02f, rng);
    t.pos = randn(size_t(77) * 512, 0.01f, rng);
    t.ln_final = {std::vector<float>(512, 1.f), std::vector<float>(512, 0.f)};
    t.proj = randn(size_t(512) * 512, 0.044f, rng);
    t.tr = random_transformer(512, 12, 8, rng);
    return c;
  }();
  return m;
}

// Multiply-add FLOPs (2 per MAC) of the vision forward at `side` x `side`.
double vision_flops(int side, bool dense) {
  const double w = 768, np = double(side / 16) * (side / 16), n = np + 1;
  double f = 2 * np * w * 768;  // patch embedding
  const double per_block = 2 * n * w * (3 * w + w + 8 * w) + 4 * n * n * w;
  f += (dense ? 11 : 12) * per_block;
  if (dense) f += 2 * np * w * w * 2 + 2 * np * w * 512;
  else f += 2 * w * 512;
  return f;
}

void BM_TextEmbedOnePhrase(benchmark::State& state) {
  const ClipModel& m = vit_b16();
  for (auto _ : state) benchmark::DoNotOptimize(m.embed_text({"a photo of a red mug on the table"}));
  state.SetItemsProcessed(state.iterations());
}
BENCHMARK(BM_TextEmbedOnePhrase)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_TextEmbed32Phrases(benchmark::State& state) {
  const ClipModel& m = vit_b16();
  std::vector<std::string> ph;
  for (int i = 0; i < 32; ++i) ph.push_back("a photo of object number " + std::to_string(i) + " on a wooden table");
  for (auto _ : state) benchmark::DoNotOptimize(m.embed_text(ph));
  state.SetItemsProcessed(state.iterations() * 32);  // items/s = phrases per second
}
BENCHMARK(BM_TextEmbed32Phrases)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ImageDense(benchmark::State& state) {
  const ClipModel& m = vit_b16();
  const int side = int(state.range(0));
  std::mt19937 rng(2);
  auto x = randn(size_t(side) * side * 3, 1.f, rng);
  for (auto _ : state) benchmark::DoNotOptimize(m.dense_tensor(x.data(), side, side));
  state.counters["FLOPS"] = benchmark::Counter(vision_flops(side, true), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_ImageDense)->Arg(224)->Arg(448)->Unit(benchmark::kMillisecond)->UseRealTime();

// The dense features with the vision tower's linear layers in bfloat16 (--precision bf16).
void BM_ImageDenseBf16(benchmark::State& state) {
  static ClipModel m = [] {
    ClipModel c = vit_b16();
    c.set_precision(Precision::BF16);
    return c;
  }();
  const int side = int(state.range(0));
  std::mt19937 rng(2);
  auto x = randn(size_t(side) * side * 3, 1.f, rng);
  for (auto _ : state) benchmark::DoNotOptimize(m.dense_tensor(x.data(), side, side));
  state.SetLabel(hgs::nn::bf16_kernel_name());
  state.counters["FLOPS"] = benchmark::Counter(vision_flops(side, true), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_ImageDenseBf16)->Arg(448)->Unit(benchmark::kMillisecond)->UseRealTime();

void BM_ImageGlobal(benchmark::State& state) {
  const ClipModel& m = vit_b16();
  const int side = int(state.range(0));
  std::mt19937 rng(3);
  auto x = randn(size_t(side) * side * 3, 1.f, rng);
  for (auto _ : state) benchmark::DoNotOptimize(m.embed_image_tensor(x.data(), side, side));
  state.counters["FLOPS"] =
      benchmark::Counter(vision_flops(side, false), benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_ImageGlobal)->Arg(224)->Unit(benchmark::kMillisecond)->UseRealTime();

// The reference rate: one sgemm with the shape of the ViT-B MLP up-projection, [n, 768] x [768, 3072].
void BM_SgemmReference(benchmark::State& state) {
  const int n = int(state.range(0)), k = 768, o = 3072;
  std::mt19937 rng(4);
  auto a = randn(size_t(n) * k, 1.f, rng), b = randn(size_t(o) * k, 1.f, rng);
  std::vector<float> c(size_t(n) * o);
  for (auto _ : state) {
    cblas_sgemm(CblasRowMajor, CblasNoTrans, CblasTrans, n, o, k, 1.f, a.data(), k, b.data(), k, 0.f, c.data(), o);
    benchmark::DoNotOptimize(c.data());
  }
  state.counters["FLOPS"] = benchmark::Counter(2.0 * n * k * o, benchmark::Counter::kIsIterationInvariantRate);
}
BENCHMARK(BM_SgemmReference)->Arg(197)->Arg(785)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
