#include "core/parallel.h"

#include <omp.h>

#include <atomic>

#include "core/error.h"
#include "core/progress.h"

namespace hgs {

void parallel_for_progress(const std::string& label, long n, bool progress, const std::function<void(long)>& fn) {
  Progress bar(label, n, progress);
  std::atomic<long> done{0};
  std::string error;
#pragma omp parallel for schedule(dynamic)
  for (long i = 0; i < n; ++i) {
    try {
      fn(i);
    } catch (const std::exception& e) {
#pragma omp critical(hgs_parallel_for_error)
      if (error.empty()) error = e.what();
    }
    const long d = ++done;
    if (omp_get_thread_num() == 0) bar.update(d);
  }
  if (!error.empty()) throw Error(error);
  bar.finish();
}

}  // namespace hgs
