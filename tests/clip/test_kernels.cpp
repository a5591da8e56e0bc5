// Transformer kernels against brute-force double-precision loops, at sizes large enough to take the
// thread-pool paths (the tiny reference models run them inline).
#include <gtest/gtest.h>
#include <omp.h>

#include <atomic>
#include <cmath>
#include <random>
#include <stdexcept>

#include "clip/block.h"
#include "nn/openblas_env.h"
#include "nn/thread_pool.h"
#include "nn/transformer.h"

// OpenBLAS with the kernels hgs picks for this CPU, as in the hgs binary (nn/openblas_env.h).
HGS_OPENBLAS_PREINIT();

using namespace hgs::clip;
using namespace hgs::nn;

namespace {

std::vector<float> randv(size_t n, float scale, unsigned seed) {
  std::mt19937 rng(seed);
  std::normal_distribution<float> d(0.f, scale);
  std::vector<float> v(n);
  for (auto& x : v) x = d(rng);
  return v;
}

Linear rand_linear(int in, int out, unsigned seed) {
  return {in, out, randv(size_t(in) * out, 1.f / std::sqrt(float(in)), seed), randv(out, 0.1f, seed + 1)};
}

LayerNorm rand_ln(int c, unsigned seed) {
  auto g = randv(c, 0.2f, seed);
  for (auto& x : g) x += 1.f;
  return {g, randv(c, 0.1f, seed + 1)};
}

// Brute-force reference of one pre-LN block (double precision).
std::vector<double> ref_block(const Block& b, int heads, Activation act, const std::vector<Segment>& segs, bool causal,
                              const std::vector<float>& x0, int n) {
  const int w = b.qkv.in, hd = w / heads, m = b.fc.out;
  std::vector<double> x(x0.begin(), x0.end());
  auto ln = [&](const LayerNorm& l, const std::vector<double>& in) {
    std::vector<double> o(in.size());
    for (int i = 0; i < n; ++i) {
      double mean = 0, var = 0;
      for (int j = 0; j < w; ++j) mean += in[size_t(i) * w + j];
      mean /= w;
      for (int j = 0; j < w; ++j) var += std::pow(in[size_t(i) * w + j] - mean, 2);
      var /= w;
      for (int j = 0; j < w; ++j)
        o[size_t(i) * w + j] = (in[size_t(i) * w + j] - mean) / std::sqrt(var + 1e-5) * l.g[j] + l.b[j];
    }
    return o;
  };
  auto lin = [&](const Linear& l, const std::vector<double>& in) {
    std::vector<double> o(size_t(n) * l.out);
    for (int i = 0; i < n; ++i)
      for (int r = 0; r < l.out; ++r) {
        double s = l.b[r];
        for (int k = 0; k < l.in; ++k) s += double(l.w[size_t(r) * l.in + k]) * in[size_t(i) * l.in + k];
        o[size_t(i) * l.out + r] = s;
      }
    return o;
  };
  auto h = ln(b.ln1, x);
  auto qkv = lin(b.qkv, h);
  std::vector<double> att(size_t(n) * w, 0.0);
  for (auto& sg : segs)
    for (int hh = 0; hh < heads; ++hh)
      for (int i = 0; i < sg.len; ++i) {
        std::vector<double> p(sg.len, 0.0);
        double mx = -1e300, sum = 0;
        const int lim = causal ? i + 1 : sg.len;
        for (int j = 0; j < lim; ++j) {
          double s = 0;
          for (int d = 0; d < hd; ++d)
            s += qkv[size_t(sg.start + i) * 3 * w + hh * hd + d] * qkv[size_t(sg.start + j) * 3 * w + w + hh * hd + d];
          p[j] = s / std::sqrt(double(hd));
          mx = std::max(mx, p[j]);
        }
        for (int j = 0; j < lim; ++j) sum += (p[j] = std::exp(p[j] - mx));
        for (int d = 0; d < hd; ++d) {
          double o = 0;
          for (int j = 0; j < lim; ++j) o += p[j] / sum * qkv[size_t(sg.start + j) * 3 * w + 2 * w + hh * hd + d];
          att[size_t(sg.start + i) * w + hh * hd + d] = o;
        }
      }
  auto a = lin(b.out, att);
  for (size_t i = 0; i < x.size(); ++i) x[i] += a[i];
  h = ln(b.ln2, x);
  Linear fc = b.fc;
  auto f = lin(fc, h);
  for (auto& v : f)
    v = act == Activation::GELU ? 0.5 * v * (1 + std::erf(v / std::sqrt(2.0))) : v / (1 + std::exp(-1.702 * v));
  std::vector<double> fo(size_t(n) * w);
  for (int i = 0; i < n; ++i)
    for (int r = 0; r < w; ++r) {
      double s = b.proj.b[r];
      for (int k = 0; k < m; ++k) s += double(b.proj.w[size_t(r) * m + k]) * f[size_t(i) * m + k];
      fo[size_t(i) * w + r] = s;
    }
  for (size_t i = 0; i < x.size(); ++i) x[i] += fo[i];
  return x;
}

}  // namespace

TEST(ClipKernels, ParallelForCoversRangeOnce) {
  for (long n : {0L, 1L, 7L, 100000L}) {
    std::vector<std::atomic<int>> hits(size_t(std::max(n, 1L)));
    parallel_for(n, 1, [&](long b, long e) {
      for (long i = b; i < e; ++i) hits[size_t(i)]++;
    });
    for (long i = 0; i < n; ++i) ASSERT_EQ(hits[size_t(i)].load(), 1) << "n " << n << " i " << i;
  }
}

TEST(ClipKernels, NestedParallelForRunsInline) {
  omp_set_num_threads(2);
  std::atomic<long> total{0};
  parallel_for(8, 1, [&](long b, long e) {
    for (long i = b; i < e; ++i) parallel_for(1000, 1, [&](long b2, long e2) { total += e2 - b2; });
  });
  EXPECT_EQ(total.load(), 8000);
}

TEST(ClipKernels, ParallelForRethrowsAWorkersExceptionAndStaysUsable) {
  omp_set_num_threads(3);
  // The last chunk runs on a worker thread (the caller takes the first): its exception reaches the caller.
  std::atomic<long> done{0};
  EXPECT_THROW(parallel_for(300, 1,
                            [&](long b, long e) {
                              if (e == 300) throw std::runtime_error("chunk failed");
                              done += e - b;
                            }),
               std::runtime_error);
  EXPECT_EQ(done.load(), 200);  // the other chunks ran to their end
  std::atomic<long> total{0};
  parallel_for(300, 1, [&](long b, long e) { total += e - b; });  // the pool took the next job
  EXPECT_EQ(total.load(), 300);
  omp_set_num_threads(2);
}

TEST(ClipKernels, BlockMatchesBruteForce) {
  omp_set_num_threads(2);  // make sure the pool path runs even on a 1-core machine
  const int w = 64, heads = 4, n = 300;
  Block b;
  b.ln1 = rand_ln(w, 1);
  b.ln2 = rand_ln(w, 3);
  b.qkv = rand_linear(w, 3 * w, 5);
  b.out = rand_linear(w, w, 7);
  b.fc = rand_linear(w, 4 * w, 9);
  b.proj = rand_linear(4 * w, w, 11);
  for (int nn : {n, 11})  // sgemm path and few-rows path
    for (bool causal : {false, true})
      for (Activation act : {Activation::GELU, Activation::QuickGELU}) {
        std::vector<Segment> segs = causal ? std::vector<Segment>{{0, nn * 2 / 5}, {nn * 2 / 5, nn - nn * 2 / 5}}
                                           : std::vector<Segment>{{0, nn}};
        auto x = randv(size_t(nn) * w, 1.f, 13);
        auto ref = ref_block(b, heads, act, segs, causal, x, nn);
        Workspace ws;
        ws.reserve(nn, w, 4 * w, nn);
        block_forward(b, heads, act, segs, causal, x.data(), nn, ws);
        double worst = 0;
        for (size_t i = 0; i < x.size(); ++i)
          worst = std::max(worst, std::fabs(x[i] - ref[i]) / (1 + std::fabs(ref[i])));
        EXPECT_LT(worst, 2e-5) << "n " << nn << " causal " << causal << " act " << int(act);
      }
}

// linear / linear_add for few rows (own kernel) and many rows (sgemm) against a double loop.
TEST(ClipKernels, LinearBothPaths) {
  omp_set_num_threads(2);
  Linear l = rand_linear(200, 300, 31);
  for (int n : {1, 5, 12, 13, 80}) {
    auto x = randv(size_t(n) * 200, 1.f, 33);
    auto y0 = randv(size_t(n) * 300, 1.f, 35);
    std::vector<float> y(size_t(n) * 300), ya = y0;
    linear(l, x.data(), n, y.data());
    linear_add(l, x.data(), n, ya.data());
    for (int i = 0; i < n; ++i)
      for (int r = 0; r < 300; ++r) {
        double s = l.b[r];
        for (int k = 0; k < 200; ++k) s += double(l.w[size_t(r) * 200 + k]) * x[size_t(i) * 200 + k];
        ASSERT_NEAR(y[size_t(i) * 300 + r], s, 2e-5 * (1 + std::fabs(s))) << "n " << n;
        ASSERT_NEAR(ya[size_t(i) * 300 + r], s + y0[size_t(i) * 300 + r], 2e-5 * (1 + std::fabs(s))) << "n " << n;
      }
  }
}

TEST(ClipKernels, LayerNormAndSoftmaxLarge) {
  omp_set_num_threads(2);
  const int n = 700, c = 96;
  auto x = randv(size_t(n) * c, 2.f, 21);
  LayerNorm ln = rand_ln(c, 23);
  std::vector<float> y(x.size());
  layer_norm(ln, x.data(), n, c, y.data());
  for (int i = 0; i < n; i += 37) {
    double mean = 0, var = 0;
    for (int j = 0; j < c; ++j) mean += x[size_t(i) * c + j];
    mean /= c;
    for (int j = 0; j < c; ++j) var += std::pow(x[size_t(i) * c + j] - mean, 2);
    var /= c;
    for (int j = 0; j < c; ++j)
      EXPECT_NEAR(y[size_t(i) * c + j], (x[size_t(i) * c + j] - mean) / std::sqrt(var + 1e-5) * ln.g[j] + ln.b[j],
                  1e-5);
  }
  std::vector<float> s = x;
  softmax_rows(s.data(), n, c, true, 0);
  for (int i = 0; i < n; i += 41) {
    const int lim = std::min(c, i + 1);
    double mx = -1e300, sum = 0;
    for (int j = 0; j < lim; ++j) mx = std::max(mx, double(x[size_t(i) * c + j]));
    for (int j = 0; j < lim; ++j) sum += std::exp(x[size_t(i) * c + j] - mx);
    for (int j = 0; j < c; ++j) {
      double e = j < lim ? std::exp(x[size_t(i) * c + j] - mx) / sum : 0.0;
      EXPECT_NEAR(s[size_t(i) * c + j], e, 1e-6);
    }
  }
}
