// A small blocking thread pool for the element-wise loops of the CLIP and SAM forward passes (softmax, LayerNorm,
// activations). Its workers sleep on a condition variable between jobs instead of spinning like OpenMP's, so
// they do not steal the cores from OpenBLAS's threads during the matrix products that run in between.
#pragma once
#include <functional>

namespace hgs::nn {

// Calls fn(begin, end) on disjoint chunks covering [0, n), in parallel on up to `threads()` threads (the
// calling thread takes the first chunk). Runs inline when n < min_parallel or one thread is configured. If a
// chunk throws, the other chunks still run to their end and the first exception is rethrown here.
void parallel_for(long n, long min_parallel, const std::function<void(long, long)>& fn);

// Worker count: omp_get_max_threads() (so --threads applies), at most 64.
int pool_threads();

// Sets the thread count of OpenBLAS and OpenMP, and with it the pool's (0 = leave the defaults: all cores); a
// count above core/threads.h's max_threads() is an hgs::Error.
void set_num_threads(int n);

}  // namespace hgs::nn
