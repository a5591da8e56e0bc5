// Running the external programs `hgs prepare` drives (Debian's colmap and ffmpeg): found in PATH (or at a path
// the user gives), started with posix_spawn, stdin from /dev/null, stdout and stderr merged into one pipe whose
// lines (split at '\n' and '\r', which ffmpeg and COLMAP use for progress) are appended to a log file and handed
// to a callback (progress parsing). Failures become one-line hgs::Errors naming the program, the package that
// provides it, how it ended and the log.
#pragma once
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

namespace hgs::prepare {

struct Tool {
  std::string program;  // name searched in PATH, or a path
  std::string package;  // Debian package that provides it (named in the error when it is missing)
};

// The absolute path of `program` (a path is checked as it is; a bare name is searched in PATH), if executable.
std::optional<std::filesystem::path> find_program(const std::string& program);

// Fails with "<program> not found: install Debian's <package> package (scripts/setup does) ..." when missing.
std::filesystem::path require_tool(const Tool& tool, const std::string& option);

struct ToolRun {
  int exit_code = 0;       // when it exited
  int signal = 0;          // when a signal ended it (exit_code is then -1)
  std::string last_lines;  // the last few non-empty lines of its output (for error messages)
  bool ok() const { return signal == 0 && exit_code == 0; }
  std::string how_it_ended() const;  // "exit status 1", "killed by signal 25 (File size limit exceeded)"
};

// Runs `exe args...`, appending its merged output to `log` (created with its folder) and calling `on_line`
// (may be empty) for every line. Throws hgs::Error when it cannot be started.
ToolRun run_tool(const std::filesystem::path& exe, const std::vector<std::string>& args,
                 const std::filesystem::path& log, const std::function<void(const std::string&)>& on_line = {});

// run_tool + a one-line hgs::Error when it does not succeed: "<what> failed (<how>): <last line>; log: <log>".
void run_tool_or_fail(const std::string& what, const std::filesystem::path& exe, const std::vector<std::string>& args,
                      const std::filesystem::path& log, const std::function<void(const std::string&)>& on_line = {});

}  // namespace hgs::prepare
