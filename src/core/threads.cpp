// Thread-count bound: see threads.h.
#include "core/threads.h"

#include <fmt/format.h>

#include <thread>

#include "core/error.h"

namespace hgs {

namespace {
int hardware_threads() {
  const unsigned h = std::thread::hardware_concurrency();
  return h == 0 ? 1 : int(h);
}
}  // namespace

int max_threads() { return 4 * hardware_threads(); }

std::string threads_range_text() {
  return fmt::format("1..{} (at most 4x this machine's {} hardware threads)", max_threads(), hardware_threads());
}

int checked_threads(long long n, const std::string& what) {
  if (n < 1 || n > max_threads()) fail("{} must be {}, got {}", what, threads_range_text(), n);
  return int(n);
}

}  // namespace hgs
