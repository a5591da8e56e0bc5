// One `hgs prepare` at a time per scene folder: SCENE/prepare/lock, held with flock(2) for the whole run and
// holding the pid of the run. The kernel drops the lock when the process dies, however it dies (SIGKILL too), so
// a stale file never locks anyone out; a program the run started (COLMAP, ffmpeg) inherits it and holds it while
// it lives, so that no second run writes the same database beside a COLMAP that outlived its hgs.
#pragma once
#include <filesystem>

namespace hgs::prepare {

class SceneLock {
 public:
  // Takes the lock or fails with one line naming the folder and the pid that holds it (and whether that process
  // still runs: a program it started may hold the lock after it died).
  explicit SceneLock(const std::filesystem::path& work);
  ~SceneLock();
  SceneLock(const SceneLock&) = delete;
  SceneLock& operator=(const SceneLock&) = delete;

 private:
  int fd_ = -1;
};

}  // namespace hgs::prepare
