// Facts about the running process that benchmarks and `hgs train` report.
#pragma once

namespace hgs {

// Peak resident set size of this process so far, in MB (getrusage's ru_maxrss, which Linux gives in KiB).
double peak_rss_mb();

}  // namespace hgs
