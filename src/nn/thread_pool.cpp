// Blocking thread pool: see thread_pool.h. One job at a time (calls from several threads serialise on a mutex);
// workers are started lazily and live for the process. An exception thrown by a chunk is caught where it was
// thrown (it must not leave a worker thread) and the first one is rethrown to the caller once every chunk ended.
#include "nn/thread_pool.h"

#include <cblas.h>

#include <omp.h>

#include <algorithm>
#include <condition_variable>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

#include "core/threads.h"

namespace hgs::nn {
namespace {

class Pool {
 public:
  ~Pool() {
    {
      std::lock_guard<std::mutex> l(m_);
      stop_ = true;
    }
    cv_.notify_all();
    for (auto& t : workers_) t.join();
  }

  void run(int nthreads, long n, const std::function<void(long, long)>& fn) {
    std::lock_guard<std::mutex> job_lock(job_);
    while (int(workers_.size()) < nthreads - 1) {
      int id = int(workers_.size()) + 1;
      workers_.emplace_back([this, id] { loop(id); });
    }
    {
      std::lock_guard<std::mutex> l(m_);
      fn_ = &fn;
      n_ = n;
      parts_ = nthreads;
      pending_ = nthreads - 1;
      ++generation_;
    }
    cv_.notify_all();
    chunk(0, fn);
    std::exception_ptr err;
    {
      std::unique_lock<std::mutex> l(m_);
      done_cv_.wait(l, [&] { return pending_ == 0; });
      fn_ = nullptr;
      err = error_;
      error_ = nullptr;
    }
    if (err) std::rethrow_exception(err);
  }

 private:
  void chunk(int part, const std::function<void(long, long)>& fn) {
    long b = n_ * part / parts_, e = n_ * (part + 1) / parts_;
    if (b >= e) return;
    try {
      fn(b, e);
    } catch (...) {
      std::lock_guard<std::mutex> l(m_);
      if (!error_) error_ = std::current_exception();
    }
  }
  void loop(int id) {
    long seen = 0;
    for (;;) {
      const std::function<void(long, long)>* fn;
      {
        std::unique_lock<std::mutex> l(m_);
        cv_.wait(l, [&] { return stop_ || (generation_ != seen && id < parts_); });
        if (stop_) return;
        seen = generation_;
        fn = fn_;
      }
      chunk(id, *fn);
      std::lock_guard<std::mutex> l(m_);
      if (--pending_ == 0) done_cv_.notify_one();
    }
  }

  std::mutex job_, m_;
  std::condition_variable cv_, done_cv_;
  std::vector<std::thread> workers_;
  const std::function<void(long, long)>* fn_ = nullptr;
  std::exception_ptr error_;  // the first exception of the running job's chunks
  long n_ = 0, generation_ = 0;
  int parts_ = 1, pending_ = 0;
  bool stop_ = false;
};

Pool& pool() {
  static Pool p;
  return p;
}

}  // namespace

int pool_threads() { return std::clamp(omp_get_max_threads(), 1, 64); }

// Set while a thread runs a pool job: a nested parallel_for then runs inline instead of deadlocking.
thread_local bool tl_in_job = false;

void parallel_for(long n, long min_parallel, const std::function<void(long, long)>& fn) {
  const int t = int(std::min<long>(pool_threads(), std::max<long>(n, 1)));
  if (n < min_parallel || t <= 1 || tl_in_job) {
    if (n > 0) fn(0, n);
    return;
  }
  pool().run(t, n, [&](long b, long e) {
    const bool prev = tl_in_job;
    tl_in_job = true;
    fn(b, e);
    tl_in_job = prev;
  });
}

void set_num_threads(int n) {
  if (n <= 0) return;
  checked_threads(n, "threads");  // the callers check first (cli/command.h, python/src/train.cpp): a last guard
  openblas_set_num_threads(n);
  omp_set_num_threads(n);
}

}  // namespace hgs::nn
