// Helpers of the crash-safety tests (test_crash_safety.cpp): run `hgs` as a child process that can be killed
// (SIGKILL) or run under limits (RLIMIT_FSIZE, no CAP_DAC_OVERRIDE), and check that every file of an output
// folder is complete: PLYs load, checkpoints are whole (header parses, array sizes add up to the file size),
// JSON parses, PNGs decode.
#pragma once
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

namespace hgs::test {

struct Child {
  int pid = -1;
  std::filesystem::path err_file;  // the child's stderr
};

// Starts the built `hgs` binary with `args` (no shell). `in_child` runs in the child before exec (limits).
Child spawn_hgs(const std::vector<std::string>& args, const std::filesystem::path& log_dir,
                const std::function<void()>& in_child = {});
// Waits for the child; returns its exit status, or -signal when a signal ended it.
int wait_child(const Child& c);
// Sends SIGKILL after `ms` milliseconds unless the child ended before; returns as wait_child.
int kill_after(const Child& c, double ms);

// Checks every file under `dir` (recursively) by its kind; returns one message per incomplete or unknown file
// (empty = all complete). Named temporary files (`*.tmpXXXXXXXX`) count as failures.
std::vector<std::string> incomplete_outputs(const std::filesystem::path& dir);
// Structural check of a trainer checkpoint (magic, JSON header, arrays exactly filling the file).
bool checkpoint_complete(const std::filesystem::path& file, std::string* why = nullptr);

}  // namespace hgs::test
