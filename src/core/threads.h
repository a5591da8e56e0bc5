// The one bound on worker-thread counts: every command's --threads (cli/command.h, add_threads_option) and
// Python's hgs.set_threads check a count here, so they accept and refuse the same values with the same words.
// 0 and negatives are refused (a count of 0 used to mean "all cores" silently; leaving the option out does that),
// and so is anything above max_threads(): libgomp SIGSEGVs setting up a team of 100000 threads, and the
// per-thread scratch buffers (render binning, hybrid fusion) grow with the count.
#pragma once
#include <string>

namespace hgs {

// 4x the hardware threads (std::thread::hardware_concurrency; 4 when unknown). Why 4x and not a fixed cap: more
// threads than cores never ran faster here (the kernels are compute- or memory-bound), yet each thread costs its
// stack and scratch buffers; 4x leaves room for oversubscription experiments and for a CPU quota smaller than the
// hardware, while a typo like 100000 fails before any thread starts, on every machine.
int max_threads();

// The range as users read it: "1..8 (at most 4x this machine's 2 hardware threads)".
std::string threads_range_text();

// `n` when 1 <= n <= max_threads(); else hgs::Error "<what> must be <range>, got <n>".
int checked_threads(long long n, const std::string& what);

}  // namespace hgs
