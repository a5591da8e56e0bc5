// Parallel loops over independent items (views, files) with a progress bar. Exceptions cannot cross an
// OpenMP region, so the first error of any item is kept and rethrown after the loop as an hgs::Error.
#pragma once
#include <cstddef>
#include <functional>
#include <string>
#include <vector>

namespace hgs {

// Runs fn(i) for i in [0, n) on the OpenMP threads (dynamic schedule) with a Progress bar named `label`.
void parallel_for_progress(const std::string& label, long n, bool progress, const std::function<void(long)>& fn);

// Sets every element of v to x on the OpenMP threads (a per-step buffer of millions of values).
template <class T>
void parallel_fill(std::vector<T>& v, T x) {
  T* d = v.data();
  const long n = long(v.size());
#pragma omp parallel for simd schedule(static)
  for (long i = 0; i < n; ++i) d[i] = x;
}

}  // namespace hgs
