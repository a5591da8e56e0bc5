// OpenBLAS settings that must be in the environment before the library starts: it reads them in its own
// constructor, which runs before main() and before any constructor of the program. Not even the program's
// .preinit_array (run first) can set them with setenv, as libc installs the environment it was started with
// after that. So the preinit below re-executes the program once (its path from /proc/self/exe, same arguments) with the
// variables added, marked HGS_OPENBLAS_ENV=1; values the user set are kept, and HGS_OPENBLAS_ENV=0 turns this
// off. Put HGS_OPENBLAS_PREINIT() in one source file of each executable that runs SAM or CLIP products (hgs,
// bench_sam, bench_clip, test_nn, test_clip, test_sam). A Python process cannot re-execute itself: the package `hgs`
// sets the same two variables from openblas_core_for_this_cpu() and kOpenblasThreadTimeout before it loads the library
// (python/hgs/__init__.py).
//
// OPENBLAS_CORETYPE: Debian's OpenBLAS picks its kernels by the CPU model number, and on a virtual machine
// whose CPUID names no model it knows (seen: a 16-core Sapphire Rapids guest reporting "Intel Xeon Processor")
// it falls back to "Prescott", an SSE3 kernel: 15 GFLOP/s per core instead of 98, and every SAM / CLIP
// product 5-6x slower at every thread count (docs/sam.md "Threads"). The type is chosen here from the
// instruction sets the CPU has: SkylakeX with AVX-512 (F, VL, BW, DQ), Haswell with AVX2 + FMA, else left to
// the library.
//
// OPENBLAS_THREAD_TIMEOUT=4: the pthread build lets an idle worker spin on sched_yield for 2^28 cycles (~0.1 s)
// after each product. hgs runs its element-wise loops and attention units on its own pool (nn/thread_pool.h)
// between products, and there the spinning workers took the cores from the pool's threads (4-5 % of a 2-thread
// SAM embedding); 2^4 cycles makes them sleep at once, and waking them costs microseconds against products of
// milliseconds.
#pragma once
#include <unistd.h>

namespace hgs::nn {

// The value of OPENBLAS_THREAD_TIMEOUT set here (see above).
inline constexpr char kOpenblasThreadTimeout[] = "4";

inline const char* openblas_core_for_this_cpu() {
  __builtin_cpu_init();  // needed before the program's constructors have run
  if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl") && __builtin_cpu_supports("avx512bw") &&
      __builtin_cpu_supports("avx512dq"))
    return "SkylakeX";
  if (__builtin_cpu_supports("avx2") && __builtin_cpu_supports("fma")) return "Haswell";
  return nullptr;
}

namespace detail {
// envp's entry for `name` ("NAME="), or null. (Runs before libc is set up: plain loops only.)
inline const char* find_env(char** envp, const char* name) {
  for (char** e = envp; e && *e; ++e) {
    const char *a = *e, *b = name;
    while (*b && *a == *b) ++a, ++b;
    if (!*b) return a;
  }
  return nullptr;
}
inline void append(char* dst, const char* a, const char* b) {
  while (*a) *dst++ = *a++;
  while (*b) *dst++ = *b++;
  *dst = 0;
}
}  // namespace detail

// The .preinit_array entry: see the top of this file.
inline void set_openblas_env(int, char** argv, char** envp) {
  if (detail::find_env(envp, "HGS_OPENBLAS_ENV=")) return;  // re-executed already, or turned off
  const char* core = openblas_core_for_this_cpu();
  const bool add_core = core && !detail::find_env(envp, "OPENBLAS_CORETYPE=");
  const bool add_timeout = !detail::find_env(envp, "OPENBLAS_THREAD_TIMEOUT=");
  if (!add_core && !add_timeout) return;
  constexpr int kMax = 4096;
  static char* env[kMax + 4];
  static char core_var[64], timeout_var[64], mark[] = "HGS_OPENBLAS_ENV=1";
  int n = 0;
  for (char** e = envp; e && *e; ++e)
    if (n < kMax) env[n++] = *e;
    else return;  // an environment this large: leave it as it is
  if (add_core) detail::append(core_var, "OPENBLAS_CORETYPE=", core), env[n++] = core_var;
  if (add_timeout)
    detail::append(timeout_var, "OPENBLAS_THREAD_TIMEOUT=", kOpenblasThreadTimeout), env[n++] = timeout_var;
  env[n++] = mark;
  env[n] = nullptr;
  // The program's own path rather than /proc/self/exe, which would rename the process "exe" in ps and top.
  static char self[4096];
  const ssize_t len = readlink("/proc/self/exe", self, sizeof(self) - 1);
  if (len <= 0) return;
  self[len] = 0;
  execve(self, argv, env);  // returns only on failure: go on with the library's own choices
}

}  // namespace hgs::nn

#define HGS_OPENBLAS_PREINIT()                                                                                      \
  __attribute__((section(".preinit_array"), used)) static void (*const hgs_openblas_preinit)(int, char**, char**) = \
      &hgs::nn::set_openblas_env
