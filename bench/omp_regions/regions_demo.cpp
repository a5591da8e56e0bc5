// A program of known OpenMP regions for the omp_regions ctest (bench/tests/test_omp_regions.py): a dynamic loop of
// four chunks that sleep 30, 10, 10 and 10 ms, then 8 ms of serial code, then a region whose `single` block sleeps
// 5 ms. Under bench/omp_regions on one thread, the first region's chunks handed to 2 threads end after 30 ms
// (30 | 10 + 10 + 10), its dynamic time is 60 ms, the gap after it 8 ms and the second region's single time 5 ms.
// Each chunk also starts a nested region, which neither mode records. With HGS_REGIONS_WALL=1 on two threads the
// first region's wall time is the 30 ms of that schedule.
#include <omp.h>

#include <chrono>
#include <thread>

namespace {
void sleep_ms(int ms) { std::this_thread::sleep_for(std::chrono::milliseconds(ms)); }
}  // namespace

int main() {
#pragma omp parallel for schedule(dynamic, 1)
  for (int i = 0; i < 4; ++i) {
    sleep_ms(i == 0 ? 30 : 10);
#pragma omp parallel num_threads(2)  // nested (inactive): started by the team's threads, never recorded
    {}
  }
  sleep_ms(8);
#pragma omp parallel
  {
#pragma omp single
    sleep_ms(5);
  }
  return 0;
}
