#include <gtest/gtest.h>
#include <omp.h>

#include "core/process.h"

using namespace hgs;

TEST(AvailableCpus, CgroupCpuMaxText) {
  EXPECT_EQ(cpus_of_cpu_max("max 100000\n"), 0);       // unlimited
  EXPECT_EQ(cpus_of_cpu_max("1600000 100000\n"), 16);  // 16 CPUs
  EXPECT_EQ(cpus_of_cpu_max("150000 100000"), 2);      // 1.5 CPUs: rounded up
  EXPECT_EQ(cpus_of_cpu_max("50000 100000"), 1);
  EXPECT_EQ(cpus_of_cpu_max("-1 100000"), 0);  // cgroup v1's unlimited quota
  EXPECT_EQ(cpus_of_cpu_max(""), 0);
  EXPECT_EQ(cpus_of_cpu_max("garbage"), 0);
  EXPECT_EQ(cpus_of_cpu_max("100000 0"), 0);
}

TEST(AvailableCpus, AtLeastOneAndAtMostTheVisibleCpus) {
  const int n = available_cpus();
  EXPECT_GE(n, 1);
  EXPECT_LE(n, omp_get_num_procs());
}
