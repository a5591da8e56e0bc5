// core/parallel.h's parallel_offsets against the serial running sum: the same offsets and total, and each(i, off)
// called once per item with its offset, for item counts below, at and above the thread count, at 1, 3 and 8
// threads.
#include <gtest/gtest.h>
#include <omp.h>

#include <cstddef>
#include <string>
#include <vector>

#include "core/parallel.h"

TEST(ParallelOffsets, MatchTheSerialRunningSumAtAnyThreadCount) {
  const int threads = omp_get_max_threads();
  for (int t : {1, 3, 8}) {
    omp_set_num_threads(t);
    for (int n : {0, 1, 2, 7, 1000, 100003}) {
      auto count = [](int i) { return size_t((i * 7919) % 13 == 0 ? 0 : (i * 31) % 17); };  // zeros among them
      std::vector<size_t> want(size_t(n) + 1, 0);
      for (int i = 0; i < n; ++i) want[size_t(i) + 1] = want[size_t(i)] + count(i);
      std::vector<size_t> got(size_t(n) + 1, 12345), seen(size_t(n), 12345);
      std::vector<int> calls(size_t(n), 0);
      hgs::parallel_offsets(n, got.data(), count, [&](int i, size_t off) {
        seen[size_t(i)] = off;
        ++calls[size_t(i)];
      });
      const std::string tag = std::to_string(n) + " items, " + std::to_string(t) + " threads";
      ASSERT_EQ(got, want) << tag;
      for (int i = 0; i < n; ++i) {
        ASSERT_EQ(calls[size_t(i)], 1) << tag << ", item " << i;
        ASSERT_EQ(seen[size_t(i)], want[size_t(i)]) << tag << ", item " << i;
      }
    }
  }
  omp_set_num_threads(threads);
}
