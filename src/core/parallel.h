// Parallel loops over independent items (views, files) with a progress bar (exceptions cannot cross an OpenMP
// region, so the first error of any item is kept and rethrown after the loop as an hgs::Error), a parallel fill,
// a running sum of per-item counts on the threads, and sums whose bits do not depend on the thread count.
#pragma once
#include <omp.h>

#include <algorithm>
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

#include "core/scratch_vector.h"

namespace hgs {

// Runs fn(i) for i in [0, n) on the OpenMP threads (dynamic schedule) with a Progress bar named `label`.
void parallel_for_progress(const std::string& label, long n, bool progress, const std::function<void(long)>& fn);

// Items per chunk of a dynamic schedule over `count` items of uneven cost (say, only the visible Gaussians do
// work, and after densification those cluster by index, so a static split leaves threads idle): about 512 chunks
// at any size (32 per thread at 16 threads), at least min_items each (a chunk costs the scheduler an atomic add).
// Where each item writes only its own outputs, the chunking changes no bits.
inline int demand_chunk(long count, int min_items) { return int(std::max<long>(min_items, count / 512)); }

// Sets every element of v to x on the OpenMP threads (a per-step buffer of millions of values).
template <class T>
void parallel_fill(std::vector<T>& v, T x) {
  T* d = v.data();
  const long n = long(v.size());
#pragma omp parallel for simd schedule(static)
  for (long i = 0; i < n; ++i) d[i] = x;
}

// off [n + 1]: off[i] = count(0) + ... + count(i - 1), off[n] the total, on the OpenMP threads in one block of items
// per thread (the blocks' totals, their running sum, then each block's own: integer counts give the serial pass's
// values), then each(i, off[i]) for every item on its block's thread. (A serial running sum over the Gaussians was
// the longest serial stretch of a 16-thread step.)
template <class Off, class Count, class Each>
void parallel_offsets(int n, Off* off, Count&& count, Each&& each) {
  std::vector<Off> block(size_t(std::max(1, omp_get_max_threads())) + 1, Off(0));
#pragma omp parallel
  {
    const int t = omp_get_thread_num(), nt = omp_get_num_threads();
    const int i0 = int(long(n) * t / nt), i1 = int(long(n) * (t + 1) / nt);
    Off sum = 0;
    for (int i = i0; i < i1; ++i) sum += Off(count(i));
    block[size_t(t) + 1] = sum;
#pragma omp barrier
#pragma omp single
    for (int b = 1; b <= nt; ++b) block[b] += block[b - 1];
    Off o = block[t];
    for (int i = i0; i < i1; ++i) {
      off[i] = o;
      each(i, o);
      o += Off(count(i));
    }
    if (t == nt - 1) off[n] = o;
  }
}

// [0, n) cut into chunks whose bounds depend on n alone, never on the thread count: `size` items each (at least
// min_size, and as many as it takes to make at most max_count chunks), the last one shorter.
struct FixedChunks {
  long n = 0, size = 1;
  int count = 0;
  FixedChunks(long n_items, long min_size, int max_count)
      : n(std::max(0L, n_items)),
        size(std::max({1L, min_size, (n + max_count - 1) / std::max(1, max_count)})),
        count(int((n + size - 1) / size)) {}
  long begin(int c) const { return std::min(n, long(c) * size); }
  long end(int c) const { return std::min(n, long(c + 1) * size); }
};

// out [width] = the sum over items [0, n) of their terms, the same bits at any thread count: body(i0, i1, part)
// adds the terms of items [i0, i1) to part [width] (zeroed before), once per chunk of `chunks` on whichever thread
// takes it, and out[k] = 0 + part_0[k] + part_1[k] + ... in chunk order. (A partial per thread, added in thread
// order, gave other bits on another thread count: the same training on 2 and on 16 cores ended in different models.)
template <class T, class Body>
void chunked_sum(const FixedChunks& chunks, size_t width, T* out, Body&& body) {
  ScratchVector<T> part(size_t(chunks.count) * width);  // each chunk zeroes its own on its thread (no serial fill)
#pragma omp parallel for schedule(dynamic, 1)
  for (int c = 0; c < chunks.count; ++c) {
    T* p = part.data() + size_t(c) * width;
    std::fill(p, p + width, T(0));
    body(chunks.begin(c), chunks.end(c), p);
  }
  const long w = long(width);
#pragma omp parallel for schedule(static) if (w * chunks.count > 65536)
  for (long k = 0; k < w; ++k) {
    T s = T(0);
    for (int c = 0; c < chunks.count; ++c) s += part[size_t(c) * width + size_t(k)];
    out[k] = s;
  }
}

}  // namespace hgs
