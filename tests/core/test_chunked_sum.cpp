// FixedChunks and chunked_sum (core/parallel.h): chunk bounds that depend on the item count alone, and sums whose
// bits are the same at every thread count (a serial loop over the same chunks, their partials added in order).
#include <gtest/gtest.h>
#include <omp.h>

#include <cmath>
#include <cstring>
#include <random>
#include <vector>

#include "core/parallel.h"

using namespace hgs;

TEST(FixedChunks, CoverTheItemsInBoundedChunks) {
  for (long n : {0L, 1L, 7L, 1023L, 1024L, 1025L, 65536L, 300001L})
    for (long min_size : {1L, 100L, 1024L})
      for (int max_count : {1, 3, 64}) {
        SCOPED_TRACE(testing::Message() << "n " << n << " min " << min_size << " max " << max_count);
        const FixedChunks c(n, min_size, max_count);
        EXPECT_LE(c.count, max_count);
        EXPECT_EQ(c.begin(0), 0);
        EXPECT_EQ(c.end(c.count - 1 < 0 ? 0 : c.count - 1), n);
        for (int k = 0; k < c.count; ++k) {
          EXPECT_LT(c.begin(k), c.end(k));  // no empty chunk
          if (k + 1 < c.count) {
            EXPECT_EQ(c.end(k), c.begin(k + 1));
            EXPECT_GE(c.end(k) - c.begin(k), min_size);
          }
        }
      }
  EXPECT_EQ(FixedChunks(5000, 1024, 64).count, 5);  // at least 1024 items a chunk
  EXPECT_EQ(FixedChunks(300000, 1024, 64).count, 64);
}

TEST(ChunkedSum, SameBitsAtEveryThreadCountAsTheSerialChunks) {
  std::mt19937 rng(11);
  const long n = 50021;
  const size_t width = 7;
  // Terms of very different magnitudes: any other order of addition rounds differently.
  std::vector<float> x(size_t(n) * width);
  for (auto& v : x) v = std::ldexp(std::uniform_real_distribution<float>(-1, 1)(rng), int(rng() % 40) - 20);
  const FixedChunks chunks(n, 1000, 16);
  ASSERT_GT(chunks.count, 8);
  auto body = [&](long i0, long i1, float* part) {
    for (long i = i0; i < i1; ++i)
      for (size_t k = 0; k < width; ++k) part[k] += x[size_t(i) * width + k];
  };
  // The reference: each chunk summed on its own, then the chunks in order.
  std::vector<float> ref(width, 0.f), serial(width, 0.f);
  for (size_t k = 0; k < width; ++k) {
    for (int c = 0; c < chunks.count; ++c) {
      float p = 0;
      for (long i = chunks.begin(c); i < chunks.end(c); ++i) p += x[size_t(i) * width + k];
      ref[k] += p;
    }
    for (long i = 0; i < n; ++i) serial[k] += x[size_t(i) * width + k];
  }
  EXPECT_NE(std::memcmp(ref.data(), serial.data(), width * sizeof(float)), 0)
      << "the terms should round differently in another order (else this test shows nothing)";
  const int threads = omp_get_max_threads();
  for (int t : {1, 2, 3, 4, 7}) {
    omp_set_num_threads(t);
    std::vector<float> out(width, -1.f);
    chunked_sum(chunks, width, out.data(), body);
    EXPECT_EQ(std::memcmp(out.data(), ref.data(), width * sizeof(float)), 0) << t << " threads";
  }
  omp_set_num_threads(threads);
  std::vector<float> none(3, -1.f);
  chunked_sum(FixedChunks(0, 10, 4), 3, none.data(), body);
  EXPECT_EQ(none, std::vector<float>(3, 0.f));  // no items: zeros
}
