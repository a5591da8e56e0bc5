// External programs through fork + exec with one merged output pipe, in their own process group (see run_tool.h).
#include "prepare/run_tool.h"

#include <fcntl.h>
#include <sys/prctl.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <unistd.h>

#include <atomic>
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

namespace {

// The process group of the program running now (0 = none): SIGTERM, SIGINT and SIGHUP to hgs end it too (it runs
// in its own group, so a Ctrl-C at the terminal no longer reaches it directly), then take their earlier action.
std::atomic<pid_t> g_child_group{0};
constexpr int kForwarded[] = {SIGTERM, SIGINT, SIGHUP};
struct sigaction g_before[3];

void forward_and_reraise(int sig) {
  const pid_t g = g_child_group.load();
  if (g > 0) kill(-g, SIGTERM);
  for (int i = 0; i < 3; ++i)
    if (kForwarded[i] == sig) sigaction(sig, &g_before[i], nullptr);
  raise(sig);  // blocked while this handler runs: the earlier action takes it on return
}

// While alive: the signal handlers above are installed and `group` is the one they end.
class ChildGuard {
 public:
  explicit ChildGuard(pid_t group) {
    struct sigaction sa {};
    sa.sa_handler = forward_and_reraise;
    sigemptyset(&sa.sa_mask);
    for (int i = 0; i < 3; ++i) sigaction(kForwarded[i], &sa, &g_before[i]);
    g_child_group.store(group);
  }
  ~ChildGuard() {
    for (int i = 0; i < 3; ++i) sigaction(kForwarded[i], &g_before[i], nullptr);
    g_child_group.store(0);
  }
  ChildGuard(const ChildGuard&) = delete;
  ChildGuard& operator=(const ChildGuard&) = delete;
};

// fork + exec with only async-signal-safe calls in the child: its own process group, SIGKILL when hgs dies
// (PR_SET_PDEATHSIG: also on SIGKILL, which no handler sees), stdin /dev/null, stdout and stderr to `out_fd`.
// Returns the pid, or fails with errno's message.
pid_t spawn_in_own_group(const fs::path& exe, std::vector<char*>& argv, int out_fd) {
  const pid_t parent = getpid();
  const pid_t pid = fork();
  if (pid < 0) fail("{}: cannot start: {}", exe.string(), strerror(errno));
  if (pid == 0) {
    setpgid(0, 0);
    prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (getppid() != parent) _exit(127);  // hgs died before the line above
    const int in = open("/dev/null", O_RDONLY);
    if (in >= 0) dup2(in, 0);
    dup2(out_fd, 1);
    dup2(out_fd, 2);
    execve(exe.c_str(), argv.data(), environ);
    const char msg[] = "hgs: cannot execute the program\n";
    [[maybe_unused]] ssize_t n = write(2, msg, sizeof msg - 1);
    _exit(127);
  }
  setpgid(pid, pid);  // also here, so that the group exists before a signal handler may use it
  return pid;
}

}  // namespace

bool is_write_failure_line(const std::string& line) {
  for (const char* s : {"SQLite error [", "database or disk is full", "No space left on device", "disk I/O error"})
    if (line.find(s) != std::string::npos) return true;
  return false;
}

ToolRun run_tool(const fs::path& exe, const std::vector<std::string>& args, const fs::path& log,
                 const std::function<void(const std::string&)>& on_line) {
  ensure_dir(log.parent_path());
  std::ofstream out(log, std::ios::app);
  if (!out) fail("{}: cannot write the log file", log.string());
  int pipefd[2];
  if (pipe2(pipefd, O_CLOEXEC) != 0) fail("cannot create a pipe for {}: {}", exe.string(), strerror(errno));
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
  try {
    pid = spawn_in_own_group(exe, argv, pipefd[1]);
  } catch (...) {
    close(pipefd[0]);
    close(pipefd[1]);
    throw;
  }
  ChildGuard guard(pid);
  close(pipefd[1]);
  ToolRun r;
  std::deque<std::string> tail;
  std::string line;
  auto emit = [&] {
    if (line.empty()) return;
    out << line << '\n';
    if (on_line) on_line(line);
    if (r.write_failure.empty() && is_write_failure_line(line)) r.write_failure = line;
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
  if (r.ok() && !r.write_failure.empty())
    fail("{} could not write its output although it exited 0 (is the disk full?): {}; log: {}", what, r.write_failure,
         log.string());
  if (r.ok()) return;
  std::string last = r.last_lines;
  if (size_t nl = last.rfind('\n'); nl != std::string::npos) last = last.substr(nl + 1);
  fail("{} failed ({}){}; log: {}", what, r.how_it_ended(), last.empty() ? "" : ": " + last, log.string());
}

}  // namespace hgs::prepare
