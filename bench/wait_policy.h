// OMP_WAIT_POLICY as a benchmark finds it. Passive waiting makes OpenMP threads sleep at every barrier, which made a
// 16-thread step 4x slower (docs/performance.md); the test suite sets it for its child processes, so a benchmark
// started from such an environment would time something else. Each benchmark program warns once on stderr.
#pragma once
#include <cstdio>
#include <cstdlib>
#include <string>

namespace hgs::bench {

// The variable's value, or a description of the default when it is unset; warns on stderr when it is passive.
inline std::string omp_wait_policy_checked() {
  const char* v = std::getenv("OMP_WAIT_POLICY");
  if (v && (std::string(v) == "passive" || std::string(v) == "PASSIVE"))
    std::fprintf(stderr, "warning: OMP_WAIT_POLICY=passive: timings are not comparable; unset it for benchmarks\n");
  return v && *v ? v : "unset (active spinning, then sleep)";
}

}  // namespace hgs::bench
