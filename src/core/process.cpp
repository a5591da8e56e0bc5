#include "core/process.h"

#include <sched.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <sstream>

namespace hgs {

double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / 1024.0;
}

int cpus_of_cpu_max(const std::string& text) {
  std::istringstream in(text);
  std::string quota;
  double period = 0;
  if (!(in >> quota >> period) || quota == "max" || period <= 0) return 0;
  char* end = nullptr;
  const double q = std::strtod(quota.c_str(), &end);
  if (end == quota.c_str() || q <= 0) return 0;
  return int(std::ceil(q / period));
}

namespace {

std::string read_small(const char* path) {
  std::ifstream f(path);
  std::stringstream s;
  s << f.rdbuf();
  return f ? s.str() : std::string();
}

int cgroup_quota_cpus() {
  if (int n = cpus_of_cpu_max(read_small("/sys/fs/cgroup/cpu.max")); n > 0) return n;
  const std::string q = read_small("/sys/fs/cgroup/cpu/cpu.cfs_quota_us"),
                    p = read_small("/sys/fs/cgroup/cpu/cpu.cfs_period_us");
  return q.empty() || p.empty() ? 0 : cpus_of_cpu_max(q + " " + p);  // v1: quota -1 when unlimited
}

}  // namespace

int available_cpus() {
  cpu_set_t set;
  CPU_ZERO(&set);
  int n = sched_getaffinity(0, sizeof(set), &set) == 0 ? CPU_COUNT(&set) : int(sysconf(_SC_NPROCESSORS_ONLN));
  n = std::max(n, 1);
  if (const int q = cgroup_quota_cpus(); q > 0) n = std::min(n, q);
  return n;
}

}  // namespace hgs
