// Writing a folder as one change: see folder.h.
#include "core/folder.h"

#include <fcntl.h>
#include <stdio.h>
#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <string>
#include <system_error>

#include "core/error.h"

namespace hgs {
namespace {

std::string errno_text(int e) { return std::error_code(e, std::generic_category()).message(); }

fs::path sibling(const fs::path& dir, const char* suffix) {
  std::string name = ".";  // (not "." + ...: GCC 12 warns of a false -Wrestrict there)
  name += dir.filename().string();
  name += suffix;
  return dir.parent_path() / name;
}

void remove_tree(const fs::path& p) {
  std::error_code ec;
  fs::remove_all(p, ec);  // best effort: a leftover is removed by the next write
}

// Flushes a folder's entries (the names linked or renamed into it) to the disk.
void sync_dir(const fs::path& dir) {
  const int fd = ::open(dir.c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (fd < 0) return;
  ::fsync(fd);
  ::close(fd);
}

// Mirrors `from` into the new folder `to`: folders made, files hard-linked (copied where links are refused),
// symlinks copied as links. `dev`: the file system of the model folder; another one inside it is refused, as are
// sockets, devices and pipes (removing the old folder afterwards must never reach outside it).
void mirror(const fs::path& from, const fs::path& to, dev_t dev, const fs::path& shown, size_t& entries) {
  for (const fs::directory_entry& e : fs::directory_iterator(from)) {
    const fs::path src = e.path(), dst = to / src.filename();
    if (++entries > kMaxFolderEntries)
      fail(
          "{}: holds more than {} files and folders; not replacing it as a whole (write the model into a folder of "
          "its own)",
          shown.string(), kMaxFolderEntries);
    struct stat st {};
    if (::lstat(src.c_str(), &st) != 0) fail("{}: cannot read ({})", src.string(), errno_text(errno));
    if (S_ISLNK(st.st_mode)) {
      fs::copy_symlink(src, dst);
    } else if (S_ISDIR(st.st_mode)) {
      if (st.st_dev != dev)
        fail("{}: another file system is mounted inside the folder; not replacing it", src.string());
      fs::create_directory(dst, src);
      mirror(src, dst, dev, shown, entries);
    } else if (S_ISREG(st.st_mode)) {
      if (::link(src.c_str(), dst.c_str()) != 0) {
        std::error_code ec;
        fs::copy_file(src, dst, ec);
        if (ec) fail("{}: cannot keep {} in the new folder ({})", shown.string(), src.string(), ec.message());
      }
    } else {
      fail("{}: not a file or folder, cannot replace the folder holding it", src.string());
    }
  }
}

void swap_in(const fs::path& shown, const std::function<void(const fs::path&)>& write) {
  std::error_code ec;
  fs::path dir = fs::absolute(shown).lexically_normal();  // "out/", "./out", "out/." -> ".../out"
  if (dir.filename().empty()) dir = dir.parent_path();
  if (fs::is_symlink(dir, ec)) dir = fs::canonical(dir);
  if (dir.filename().empty() || dir == dir.root_path()) fail("{}: not a folder that can be replaced", shown.string());
  const fs::path tmp = sibling(dir, ".hgs-new"), old = sibling(dir, ".hgs-old");
  // A folder missing with a complete old copy beside it: a kill between the two renames of the fallback swap.
  if (!fs::exists(dir, ec) && fs::is_directory(old, ec)) fs::rename(old, dir, ec);
  remove_tree(tmp);  // a leftover of a killed write
  remove_tree(old);
  const bool existed = fs::exists(dir, ec);
  if (existed && !fs::is_directory(dir, ec)) fail("{}: exists and is not a folder", shown.string());
  fs::create_directories(dir.parent_path(), ec);
  if (::mkdir(tmp.c_str(), 0777) != 0) fail("{}: cannot write ({})", shown.string(), errno_text(errno));
  mode_t mode = 0;
  try {
    if (existed) {
      struct stat st {};
      if (::stat(dir.c_str(), &st) != 0) fail("{}: cannot read ({})", shown.string(), errno_text(errno));
      mode = st.st_mode & 07777;
      size_t entries = 0;
      mirror(dir, tmp, st.st_dev, shown, entries);
    }
    write(tmp);
    if (existed) ::chmod(tmp.c_str(), mode);  // the folder keeps its permissions
    sync_dir(tmp);
    // A process working inside the folder (Model.save("."), hgs train --out .) would be left in the old, removed
    // one: it moves to the same place in the new folder (other processes' shells there need a `cd .`).
    fs::path inside;
    if (existed) {
      std::error_code e1, e2;
      const fs::path cwd = fs::current_path(e1), real = fs::canonical(dir, e2);
      const fs::path rel = (e1 || e2) ? fs::path() : cwd.lexically_relative(real);
      if (!rel.empty() && *rel.begin() != "..") inside = rel;
    }
    auto back_inside = [&] {
      if (inside.empty()) return;
      int rc = ::chdir((dir / inside).c_str());
      if (rc != 0) rc = ::chdir(dir.c_str());  // best effort: the folder itself
      (void)rc;
    };
    if (!existed) {
      if (::rename(tmp.c_str(), dir.c_str()) != 0) fail("{}: cannot write ({})", shown.string(), errno_text(errno));
    } else if (::renameat2(AT_FDCWD, tmp.c_str(), AT_FDCWD, dir.c_str(), RENAME_EXCHANGE) == 0) {
      back_inside();
      remove_tree(tmp);  // the old folder, now under the temporary name
    } else {
      if (errno != EINVAL && errno != ENOSYS)
        fail("{}: cannot replace the folder ({})", shown.string(), errno_text(errno));
      if (::rename(dir.c_str(), old.c_str()) != 0)
        fail("{}: cannot replace the folder ({})", shown.string(), errno_text(errno));
      if (::rename(tmp.c_str(), dir.c_str()) != 0) {
        const int e = errno;
        ::rename(old.c_str(), dir.c_str());
        fail("{}: cannot replace the folder ({})", shown.string(), errno_text(e));
      }
      back_inside();
      remove_tree(old);
    }
  } catch (const Error& e) {  // name the files where they were to go, not the temporary folder
    remove_tree(tmp);
    std::string m = e.what();
    fs::path where = shown;
    if (where.filename().empty()) where = where.parent_path();
    for (size_t at; (at = m.find(tmp.string())) != std::string::npos;)
      m.replace(at, tmp.string().size(), where.string());
    throw Error(m);
  } catch (...) {
    remove_tree(tmp);
    throw;
  }
  sync_dir(dir.parent_path());
}

}  // namespace

void write_folder_whole(const fs::path& dir_in, const std::function<void(const fs::path&)>& write) {
  try {
    swap_in(dir_in, write);
  } catch (const fs::filesystem_error& e) {  // mirror's copies: one line naming the folder
    fail("{}: cannot write ({})", dir_in.string(), e.code().message());
  }
}

}  // namespace hgs
