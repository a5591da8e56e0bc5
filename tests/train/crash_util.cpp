#include "crash_util.h"

#include <fcntl.h>
#include <signal.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstring>
#include <thread>

#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "core/image.h"
#include "model/ply.h"

namespace hgs::test {
namespace fs = std::filesystem;

Child spawn_hgs(const std::vector<std::string>& args, const fs::path& log_dir, const std::function<void()>& in_child) {
  Child c;
  c.err_file = log_dir / "stderr.txt";
  std::vector<std::string> argv_s = {HGS_BINARY};
  argv_s.insert(argv_s.end(), args.begin(), args.end());
  std::vector<char*> argv;
  for (auto& s : argv_s) argv.push_back(s.data());
  argv.push_back(nullptr);
  const std::string err = c.err_file.string(), out = (log_dir / "stdout.txt").string();
  std::fflush(nullptr);
  c.pid = ::fork();
  if (c.pid == 0) {
    const int eo = ::open(err.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    const int oo = ::open(out.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (eo < 0 || oo < 0) ::_exit(126);
    ::dup2(eo, 2);
    ::dup2(oo, 1);
    if (in_child) in_child();
    ::execv(argv[0], argv.data());
    ::_exit(127);
  }
  return c;
}

int wait_child(const Child& c) {
  int st = 0;
  while (::waitpid(c.pid, &st, 0) < 0 && errno == EINTR) {
  }
  return WIFEXITED(st) ? WEXITSTATUS(st) : WIFSIGNALED(st) ? -WTERMSIG(st) : -1000;
}

int kill_after(const Child& c, double ms) {
  const auto end = std::chrono::steady_clock::now() + std::chrono::microseconds(long(ms * 1000));
  int st = 0;
  while (std::chrono::steady_clock::now() < end) {
    const int r = ::waitpid(c.pid, &st, WNOHANG);
    if (r == c.pid) return WIFEXITED(st) ? WEXITSTATUS(st) : WIFSIGNALED(st) ? -WTERMSIG(st) : -1000;
    std::this_thread::sleep_for(std::chrono::microseconds(200));
  }
  ::kill(c.pid, SIGKILL);
  return wait_child(c);
}

bool checkpoint_complete(const fs::path& file, std::string* why) {
  auto no = [&](const std::string& m) {
    if (why) *why = m;
    return false;
  };
  std::vector<uint8_t> b;
  try {
    b = read_file_bytes(file);
  } catch (const std::exception& e) {
    return no(e.what());
  }
  if (b.size() < 16 || std::memcmp(b.data(), "HGSCKPT1", 8) != 0) return no("bad magic or shorter than 16 bytes");
  uint64_t len = 0;
  std::memcpy(&len, b.data() + 8, 8);
  if (len > b.size() - 16) return no("header longer than the file");
  nlohmann::json h;
  try {
    h = nlohmann::json::parse(b.begin() + 16, b.begin() + 16 + long(len));
    uint64_t values = 0;
    for (auto& a : h.at("arrays")) values += a.at("count").get<uint64_t>();
    if (16 + len + 4 * values != b.size())
      return no("arrays hold " + std::to_string(4 * values) + " bytes, the file has " +
                std::to_string(b.size() - 16 - len));
  } catch (const std::exception& e) {
    return no(std::string("header: ") + e.what());
  }
  return true;
}

std::vector<std::string> incomplete_outputs(const fs::path& dir) {
  std::vector<std::string> bad;
  if (!fs::exists(dir)) return bad;  // killed before it made the folder: no output, none torn
  for (const auto& e : fs::recursive_directory_iterator(dir)) {
    if (!e.is_regular_file()) continue;
    // A complete copy under `<name>.hgs-replace` is the one trace atomic_write's kill window may leave (see
    // core/fs.h): it must be whole, so it is checked as the file it replaces.
    const fs::path& p = e.path();
    fs::path kind = p;
    if (kind.extension() == kReplaceSuffix) kind.replace_extension();
    const std::string name = kind.filename().string(), ext = kind.extension().string();
    const std::string where = p.lexically_relative(dir).string();
    try {
      if (name.find(".tmp") != std::string::npos) {
        bad.push_back(where + ": temporary file left behind");
      } else if (ext == ".ply") {
        read_model_ply(p);
      } else if (ext == ".ckpt") {
        std::string why;
        if (!checkpoint_complete(p, &why)) bad.push_back(where + ": " + why);
      } else if (ext == ".json") {
        [[maybe_unused]] const auto j = nlohmann::json::parse(read_file_text(p));  // throws when malformed
      } else if (ext == ".png") {
        Image img = load_image(p);
        if (img.width <= 0 || img.height <= 0) bad.push_back(where + ": empty image");
      } else if (ext == ".md") {
        const std::string t = read_file_text(p);
        if (t.empty() || t.back() != '\n') bad.push_back(where + ": does not end with a newline");
      } else if (name != "stderr.txt" && name != "stdout.txt") {
        bad.push_back(where + ": unexpected file");
      }
    } catch (const std::exception& ex) {
      bad.push_back(where + ": " + ex.what());
    }
  }
  return bad;
}

}  // namespace hgs::test
