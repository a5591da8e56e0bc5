// The scene folder's lock (scene_lock.h).
#include "prepare/scene_lock.h"

#include <fcntl.h>
#include <sys/file.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstring>
#include <string>

#include "core/error.h"

namespace hgs::prepare {

SceneLock::SceneLock(const std::filesystem::path& work) {
  const std::filesystem::path file = work / "lock";
  // Not O_CLOEXEC: the programs a run starts inherit the lock (see scene_lock.h).
  fd_ = open(file.c_str(), O_RDWR | O_CREAT, 0644);
  if (fd_ < 0) fail("{}: cannot create the lock file ({})", file.string(), strerror(errno));
  if (flock(fd_, LOCK_EX | LOCK_NB) != 0) {
    const int err = errno;
    char buf[32] = {};
    const ssize_t n = pread(fd_, buf, sizeof buf - 1, 0);
    close(fd_);
    fd_ = -1;
    if (err != EWOULDBLOCK) fail("{}: cannot lock ({})", file.string(), strerror(err));
    const long pid = n > 0 ? std::strtol(buf, nullptr, 10) : 0;
    const std::string scene = work.parent_path().string();
    if (pid > 0 && kill(pid_t(pid), 0) != 0 && errno == ESRCH)
      fail(
          "{}: another hgs prepare is writing this scene folder: pid {} has ended, but a program it started "
          "(COLMAP or ffmpeg) still runs and holds {}; wait for it to end or stop it",
          scene, pid, file.string());
    fail("{}: another hgs prepare (pid {}) is writing this scene folder; wait for it to finish or stop it", scene,
         pid > 0 ? std::to_string(pid) : "unknown");
  }
  const std::string me = std::to_string(getpid()) + "\n";
  if (ftruncate(fd_, 0) != 0 || pwrite(fd_, me.data(), me.size(), 0) != ssize_t(me.size()))
    fail("{}: cannot write the lock file ({})", file.string(), strerror(errno));
}

SceneLock::~SceneLock() {
  if (fd_ >= 0) close(fd_);  // releases the flock (a child that inherited it keeps it until it exits)
}

}  // namespace hgs::prepare
