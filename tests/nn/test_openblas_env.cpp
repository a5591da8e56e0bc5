// The OpenBLAS settings of nn/openblas_env.h reach the library: its kernels are the ones chosen for this CPU
// (or the ones the user named), never the SSE3 fallback on a CPU with AVX2.
#include <cblas.h>
#include <gtest/gtest.h>
#include <strings.h>

#include <cstdlib>
#include <string>

#include "nn/openblas_env.h"

HGS_OPENBLAS_PREINIT();

TEST(OpenBlasEnv, CoreTypeIsSetBeforeTheLibraryStarts) {
  const char* env = std::getenv("OPENBLAS_CORETYPE");
  const char* ours = hgs::nn::openblas_core_for_this_cpu();
  if (!ours && !env) GTEST_SKIP() << "no AVX2 on this CPU: the core type is left to OpenBLAS";
  ASSERT_NE(env, nullptr) << "the preinit did not run";
  const std::string core = openblas_get_corename();
  EXPECT_EQ(strcasecmp(core.c_str(), env), 0) << "OpenBLAS runs " << core << ", the environment says " << env;
  if (__builtin_cpu_supports("avx2")) {
    EXPECT_NE(strcasecmp(core.c_str(), "prescott"), 0);
  }
}

TEST(OpenBlasEnv, IdleWorkersSleepAtOnceUnlessTheUserSaidOtherwise) {
  const char* t = std::getenv("OPENBLAS_THREAD_TIMEOUT");
  ASSERT_NE(t, nullptr);
  EXPECT_GE(std::atoi(t), 1);
}
