#include "core/process.h"

#include <sys/resource.h>

namespace hgs {

double peak_rss_mb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return double(u.ru_maxrss) / 1024.0;
}

}  // namespace hgs
