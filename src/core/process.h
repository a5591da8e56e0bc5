// Facts about the running process that benchmarks and `hgs train` report.
#pragma once
#include <string>

namespace hgs {

// Peak resident set size of this process so far, in MB (getrusage's ru_maxrss, which Linux gives in KiB).
double peak_rss_mb();

// The CPUs this process may use: the affinity mask's count, lowered to the cgroup's CPU quota (cgroup v2
// cpu.max, v1 cpu.cfs_quota_us / cpu.cfs_period_us, rounded up) when there is one. A container limited by
// quota still shows every host CPU to sched_getaffinity, OpenMP and OpenBLAS; one thread per visible CPU then
// oversubscribes the quota (threads of a barrier wait for a descheduled one).
int available_cpus();

// The quota in CPUs from the text of cgroup v2's cpu.max ("max 100000" or "QUOTA PERIOD"), 0 when unlimited
// or unreadable.
int cpus_of_cpu_max(const std::string& text);

}  // namespace hgs
