// OpenMP thread count as a benchmark argument: every timing benchmark of bench_render, bench_train, bench_hybrid
// and bench_sam runs at each thread count of HGS_BENCH_THREADS (the last argument, "threads"; default "1,2"), so
// one run shows how each part scales from one core to two, or to 16 where a machine has them:
//   HGS_BENCH_THREADS=1,2,4,8,16 build/bench_hybrid     (docs/performance.md)
#pragma once
#include <benchmark/benchmark.h>
#include <omp.h>

#include <cstdint>
#include <cstdlib>
#include <exception>
#include <sstream>
#include <string>
#include <vector>

#include "render/raster_isa.h"
#include "wait_policy.h"

namespace hgs::bench {

// Sets the OpenMP thread count to the benchmark's argument `arg` for the benchmark's lifetime.
class OmpThreads {
 public:
  OmpThreads(const benchmark::State& st, int arg) : prev_(omp_get_max_threads()) {
    omp_set_num_threads(static_cast<int>(st.range(arg)));
  }
  ~OmpThreads() { omp_set_num_threads(prev_); }
  OmpThreads(const OmpThreads&) = delete;
  OmpThreads& operator=(const OmpThreads&) = delete;

 private:
  int prev_;
};

// The rasterizer compilation in use (render/raster_isa.h; HGS_RASTER_ISA=avx2|avx512 chooses), in the run's header.
inline std::string raster_isa_context() {
  try {
    return render::raster_isa_name(render::raster_isa());
  } catch (const std::exception& e) {  // a bad HGS_RASTER_ISA: say so here, the first render fails with it
    return e.what();
  }
}
inline const bool kRasterIsaContext = (benchmark::AddCustomContext("raster_isa", raster_isa_context()), true);

// OMP_WAIT_POLICY in the run's header (wait_policy.h: a warning when it is passive).
inline const bool kWaitPolicyContext =
    (benchmark::AddCustomContext("omp_wait_policy", omp_wait_policy_checked()), true);

// The thread counts to run at: HGS_BENCH_THREADS ("1,2,4,8,16"), default 1 and 2.
inline std::vector<int64_t> thread_counts() {
  std::vector<int64_t> t;
  const char* env = std::getenv("HGS_BENCH_THREADS");
  std::stringstream ss(env && *env ? env : "1,2");
  for (std::string item; std::getline(ss, item, ',');)
    if (const int n = std::atoi(item.c_str()); n > 0) t.push_back(n);
  if (t.empty()) t = {1, 2};
  return t;
}

// A benchmark without other arguments at each thread count.
inline void at_each_thread_count(benchmark::internal::Benchmark* b) {
  b->ArgName("threads");
  for (int64_t t : thread_counts()) b->Arg(t);
}

}  // namespace hgs::bench
