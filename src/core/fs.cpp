#include "core/fs.h"

#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <fstream>
#include <random>
#include <system_error>

#include "core/error.h"

namespace hgs {

std::vector<uint8_t> read_file_bytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) {
    if (!fs::exists(path)) fail("{}: file not found", path.string());
    fail("{}: cannot open for reading", path.string());
  }
  std::streamsize n = in.tellg();
  in.seekg(0);
  std::vector<uint8_t> buf(static_cast<size_t>(n));
  if (n > 0 && !in.read(reinterpret_cast<char*>(buf.data()), n)) fail("{}: read error", path.string());
  return buf;
}

std::string read_file_text(const fs::path& path) {
  auto b = read_file_bytes(path);
  return std::string(b.begin(), b.end());
}

namespace {

std::string errno_text(int e) { return std::error_code(e, std::generic_category()).message(); }

struct Fd {  // closes on scope exit
  int fd;
  ~Fd() {
    if (fd >= 0) ::close(fd);
  }
};

fs::path temp_name(const fs::path& path) {
  static thread_local std::mt19937_64 rng{std::random_device{}()};
  fs::path tmp = path;
  tmp += fmt::format(".tmp{:08x}", static_cast<uint32_t>(rng()));
  return tmp;
}

fs::path replace_name(const fs::path& path) {
  fs::path tmp = path;
  tmp += kReplaceSuffix;
  return tmp;
}

// Flushes the file `fd` to the disk: once its name appears, its bytes are there too (also across a power loss).
void sync_fd(int fd, const fs::path& path) {
  if (::fsync(fd) != 0) fail("{}: cannot write ({})", path.string(), errno_text(errno));
}

// Fallback for file systems without O_TMPFILE: named temp file, fsync, rename.
void write_via_named_temp(const fs::path& path, const std::function<void(const fs::path&)>& write) {
  const fs::path tmp = temp_name(path);
  try {
    write(tmp);
    Fd f{::open(tmp.c_str(), O_RDONLY | O_CLOEXEC)};
    if (f.fd < 0) fail("{}: cannot write ({})", path.string(), errno_text(errno));
    sync_fd(f.fd, path);
    std::error_code ec;
    fs::rename(tmp, path, ec);
    if (ec) fail("{}: cannot write ({})", path.string(), ec.message());
  } catch (...) {
    std::error_code ec;
    fs::remove(tmp, ec);
    throw;
  }
}

}  // namespace

void atomic_write(const fs::path& path, const std::function<void(const fs::path&)>& write) {
  fs::path dir = path.parent_path();
  if (!dir.empty()) ensure_dir(dir);
  // An unnamed file in the destination folder: a kill before it is linked leaves nothing behind.
  Fd f{::open(dir.empty() ? "." : dir.c_str(), O_TMPFILE | O_WRONLY | O_CLOEXEC, 0666)};
  if (f.fd < 0) {
    const int e = errno;
    if (e == EOPNOTSUPP || e == EISDIR || e == EINVAL) return write_via_named_temp(path, write);
    fail("{}: cannot write ({})", path.string(), errno_text(e));
  }
  const std::string proc = fmt::format("/proc/self/fd/{}", f.fd);
  if (::access(proc.c_str(), F_OK) != 0) return write_via_named_temp(path, write);  // no /proc
  write(proc);  // the writer reopens the unnamed file through /proc (truncating it) and closes it
  sync_fd(f.fd, path);
  if (::linkat(AT_FDCWD, proc.c_str(), AT_FDCWD, path.c_str(), AT_SYMLINK_FOLLOW) == 0) return;
  if (errno != EEXIST) fail("{}: cannot write ({})", path.string(), errno_text(errno));
  // Replacing a file: link under `<name>.hgs-replace` (complete already), then rename over the old one. Linux
  // has no atomic "link over an existing name", so a kill between the two calls leaves a complete copy under
  // that name; the name is fixed (not random) so that the next write of the same output removes it: a crashed
  // run leaves at most one such file per output, whole, and never a torn file under the output's name.
  const fs::path tmp = replace_name(path);
  for (int attempt = 0;; ++attempt) {
    if (::linkat(AT_FDCWD, proc.c_str(), AT_FDCWD, tmp.c_str(), AT_SYMLINK_FOLLOW) == 0) break;
    if (errno != EEXIST || attempt >= 8) fail("{}: cannot write ({})", path.string(), errno_text(errno));
    if (::unlink(tmp.c_str()) != 0 && errno != ENOENT)  // left by a killed run (or a concurrent writer's)
      fail("{}: cannot remove {} ({})", path.string(), tmp.filename().string(), errno_text(errno));
  }
  if (::rename(tmp.c_str(), path.c_str()) != 0) {
    const int e = errno;
    ::unlink(tmp.c_str());
    fail("{}: cannot write ({})", path.string(), errno_text(e));
  }
}

void atomic_write_bytes(const fs::path& path, const void* data, size_t size) {
  atomic_write(path, [&](const fs::path& tmp) {
    Fd f{::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0666)};
    if (f.fd < 0) fail("{}: cannot open for writing ({})", path.string(), errno_text(errno));
    const char* p = static_cast<const char*>(data);
    for (size_t done = 0; done < size;) {  // every short write is continued; an error is reported (no stream buffer)
      const ssize_t n = ::write(f.fd, p + done, std::min<size_t>(size - done, size_t(1) << 30));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) fail("{}: write error ({})", path.string(), errno_text(n < 0 ? errno : ENOSPC));
      done += size_t(n);
    }
    const int fd = f.fd;
    f.fd = -1;
    if (::close(fd) != 0) fail("{}: write error ({})", path.string(), errno_text(errno));
  });
}

void atomic_write_text(const fs::path& path, const std::string& text) {
  atomic_write_bytes(path, text.data(), text.size());
}

void ensure_dir(const fs::path& dir) {
  std::error_code ec;
  if (fs::exists(dir, ec)) {
    if (!fs::is_directory(dir, ec)) fail("{}: exists but is not a directory", dir.string());
    return;
  }
  fs::create_directories(dir, ec);
  if (ec) fail("{}: cannot create directory ({})", dir.string(), ec.message());
}

}  // namespace hgs
