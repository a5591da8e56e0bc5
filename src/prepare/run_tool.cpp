// External programs through posix_spawn with one merged output pipe (see run_tool.h).
#include "prepare/run_tool.h"

#include <fcntl.h>
#include <spawn.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstring>
#include <deque>
#include <fstream>

#include "core/error.h"
#include "core/fs.h"

extern char** environ;

namespace hgs::prepare {
namespace fs = std::filesystem;

std::optional<fs::path> find_program(const std::string& program) {
  auto executable = [](const fs::path& p) {
    std::error_code ec;
    return fs::is_regular_file(p, ec) && access(p.c_str(), X_OK) == 0;
  };
  if (program.find('/') != std::string::npos) {
    if (executable(program)) return fs::absolute(program);
    return std::nullopt;
  }
  const char* path = std::getenv("PATH");
  std::string dirs = path ? path : "/usr/local/bin:/usr/bin:/bin";
  size_t pos = 0;
  while (pos <= dirs.size()) {
    size_t e = dirs.find(':', pos);
    if (e == std::string::npos) e = dirs.size();
    fs::path dir = dirs.substr(pos, e - pos);
    if (dir.empty()) dir = ".";
    if (executable(dir / program)) return dir / program;
    pos = e + 1;
  }
  return std::nullopt;
}

fs::path require_tool(const Tool& tool, const std::string& option) {
  if (auto p = find_program(tool.program)) return *p;
  if (tool.program.find('/') != std::string::npos)
    fail("{}: not an executable file (given with {})", tool.program, option);
  fail(
      "{} not found in PATH: install Debian's {} package (`apt-get install {}`, or scripts/setup), or give its path "
      "with {}",
      tool.program, tool.package, tool.package, option);
}

std::string ToolRun::how_it_ended() const {
  if (signal) return fmt::format("killed by signal {} ({})", signal, strsignal(signal));
  return fmt::format("exit status {}", exit_code);
}

ToolRun run_tool(const fs::path& exe, const std::vector<std::string>& args, const fs::path& log,
                 const std::function<void(const std::string&)>& on_line) {
  ensure_dir(log.parent_path());
  std::ofstream out(log, std::ios::app);
  if (!out) fail("{}: cannot write the log file", log.string());
  int pipefd[2];
  if (pipe2(pipefd, O_CLOEXEC) != 0) fail("cannot create a pipe for {}: {}", exe.string(), strerror(errno));
  posix_spawn_file_actions_t fa;
  posix_spawn_file_actions_init(&fa);
  posix_spawn_file_actions_addopen(&fa, 0, "/dev/null", O_RDONLY, 0);
  posix_spawn_file_actions_adddup2(&fa, pipefd[1], 1);
  posix_spawn_file_actions_adddup2(&fa, pipefd[1], 2);
  std::vector<std::string> argv_s{exe.string()};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (std::string& s : argv_s) argv.push_back(s.data());
  argv.push_back(nullptr);
  out << "$";
  for (const std::string& s : argv_s) out << ' ' << s;
  out << '\n';
  out.flush();
  pid_t pid = 0;
  const int rc = posix_spawn(&pid, exe.c_str(), &fa, nullptr, argv.data(), environ);
  posix_spawn_file_actions_destroy(&fa);
  close(pipefd[1]);
  if (rc != 0) {
    close(pipefd[0]);
    fail("{}: cannot start: {}", exe.string(), strerror(rc));
  }
  ToolRun r;
  std::deque<std::string> tail;
  std::string line;
  auto emit = [&] {
    if (line.empty()) return;
    out << line << '\n';
    if (on_line) on_line(line);
    tail.push_back(line);
    if (tail.size() > 8) tail.pop_front();
    line.clear();
  };
  char buf[4096];
  for (;;) {
    ssize_t n = read(pipefd[0], buf, sizeof buf);
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) break;
    for (ssize_t i = 0; i < n; ++i) {
      if (buf[i] == '\n' || buf[i] == '\r') emit();
      else line.push_back(buf[i]);
    }
  }
  emit();
  close(pipefd[0]);
  int status = 0;
  while (waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFSIGNALED(status)) {
    r.signal = WTERMSIG(status);
    r.exit_code = -1;
  } else {
    r.exit_code = WEXITSTATUS(status);
  }
  for (const std::string& s : tail) r.last_lines += (r.last_lines.empty() ? "" : "\n") + s;
  out << "# " << r.how_it_ended() << '\n';
  return r;
}

void run_tool_or_fail(const std::string& what, const fs::path& exe, const std::vector<std::string>& args,
                      const fs::path& log, const std::function<void(const std::string&)>& on_line) {
  ToolRun r = run_tool(exe, args, log, on_line);
  if (r.ok()) return;
  std::string last = r.last_lines;
  if (size_t nl = last.rfind('\n'); nl != std::string::npos) last = last.substr(nl + 1);
  fail("{} failed ({}){}; log: {}", what, r.how_it_ended(), last.empty() ? "" : ": " + last, log.string());
}

}  // namespace hgs::prepare
