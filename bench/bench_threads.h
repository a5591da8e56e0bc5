// OpenMP thread count as a benchmark argument: every timing benchmark of bench_render, bench_train and bench_hybrid
// runs at 1 and at 2 threads (the last argument, "threads"), so one run shows how each part scales from one core
// to two (docs/performance.md).
#pragma once
#include <benchmark/benchmark.h>
#include <omp.h>

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
inline const bool kRasterIsaContext =
    (benchmark::AddCustomContext("raster_isa", render::raster_isa_name(render::raster_isa())), true);

// A benchmark without other arguments at 1 and 2 threads.
inline void at_1_and_2_threads(benchmark::internal::Benchmark* b) { b->ArgName("threads")->Arg(1)->Arg(2); }

}  // namespace hgs::bench
