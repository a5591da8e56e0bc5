// OpenMP thread count as a benchmark argument: every timing benchmark of bench_render, bench_train and bench_hybrid
// runs at 1 and at 2 threads (the last argument, "threads"), so one run shows how each part scales from one core
// to two (docs/performance.md).
#pragma once
#include <benchmark/benchmark.h>
#include <omp.h>

#include <exception>
#include <string>

#include "render/raster_isa.h"

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

// A benchmark without other arguments at 1 and 2 threads.
inline void at_1_and_2_threads(benchmark::internal::Benchmark* b) { b->ArgName("threads")->Arg(1)->Arg(2); }

}  // namespace hgs::bench
