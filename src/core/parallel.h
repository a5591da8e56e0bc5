// Parallel loops over independent items (views, files) with a progress bar. Exceptions cannot cross an
// OpenMP region, so the first error of any item is kept and rethrown after the loop as an hgs::Error.
#pragma once
#include <functional>
#include <string>

namespace hgs {

// Runs fn(i) for i in [0, n) on the OpenMP threads (dynamic schedule) with a Progress bar named `label`.
void parallel_for_progress(const std::string& label, long n, bool progress, const std::function<void(long)>& fn);

}  // namespace hgs
