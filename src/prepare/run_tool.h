// Running the external programs `hgs prepare` drives (Debian's colmap and ffmpeg): found in PATH (or at a path
// the user gives), started (fork + exec) in a process group of their own that dies with hgs: the program gets
// SIGKILL when the thread that started it dies, whatever killed hgs (PR_SET_PDEATHSIG; prepare runs its tools from
// the main thread), and SIGTERM / SIGINT / SIGHUP to hgs are passed on to the whole group as SIGTERM before they
// take their usual action, so no COLMAP is left writing the scene after hgs is gone. stdin is /dev/null, stdout
// and stderr are merged into one pipe whose lines (split at '\n' and '\r', which ffmpeg and COLMAP use for
// progress) are appended to a log file and handed to a callback (progress parsing). Failures become one-line
// hgs::Errors naming the program, the package that provides it, how it ended and the log.
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
  int exit_code = 0;          // when it exited
  int signal = 0;             // when a signal ended it (exit_code is then -1)
  std::string last_lines;     // the last few non-empty lines of its output (for error messages)
  std::string write_failure;  // the first output line that reports a failed write (is_write_failure_line)
  bool ok() const { return signal == 0 && exit_code == 0; }
  std::string how_it_ended() const;  // "exit status 1", "killed by signal 25 (File size limit exceeded)"
};

// Runs `exe args...`, appending its merged output to `log` (created with its folder) and calling `on_line`
// (may be empty) for every line. Throws hgs::Error when it cannot be started.
ToolRun run_tool(const std::filesystem::path& exe, const std::vector<std::string>& args,
                 const std::filesystem::path& log, const std::function<void(const std::string&)>& on_line = {});

// True when a line of a program's output reports that it could not write (an SQLite error, a full disk):
// COLMAP 3.8 logs "database or disk is full" and still exits 0.
bool is_write_failure_line(const std::string& line);

// run_tool + a one-line hgs::Error when it does not succeed: "<what> failed (<how>): <last line>; log: <log>",
// or when it exited 0 but its output reports a failed write.
void run_tool_or_fail(const std::string& what, const std::filesystem::path& exe, const std::vector<std::string>& args,
                      const std::filesystem::path& log, const std::function<void(const std::string&)>& on_line = {});

}  // namespace hgs::prepare
