// OpenBLAS's idle workers, set before the library starts them. Its pthread build (Debian's default) lets a worker
// spin on sched_yield for 2^28 cycles (~0.1 s) after each product before it sleeps. hgs runs its element-wise
// loops and the attention units of SAM and CLIP on its own pool (clip/thread_pool.h) between the products, and
// there the spinning workers took the cores from the pool's threads: 4-5 % of a 2-thread SAM embedding (bench_sam,
// docs/sam.md "Threads"). OPENBLAS_THREAD_TIMEOUT=4 (2^4 cycles) makes them sleep at once; waking them costs
// microseconds against products of milliseconds. The library reads the variable in its own constructor, before
// main() and before any constructor of the program, so it is set from the program's .preinit_array, which the
// dynamic loader runs first. A value the user set is kept. Put HGS_OPENBLAS_PREINIT() in one source file of an
// executable (it is ignored in a shared library).
#pragma once
#include <cstdlib>

namespace hgs::clip {
inline void set_openblas_env(int, char**, char**) { setenv("OPENBLAS_THREAD_TIMEOUT", "4", 0); }
}  // namespace hgs::clip

#define HGS_OPENBLAS_PREINIT()                                                                    \
  __attribute__((section(".preinit_array"), used)) static void (*const hgs_openblas_preinit)( \
      int, char**, char**) = &hgs::clip::set_openblas_env
