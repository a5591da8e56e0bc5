// Writing a folder as one change (issue 60: a second Ctrl-C while hgs.train saved left point_cloud.ply without
// config.json / train_stats.json). write_folder_whole fills a temporary sibling folder `.NAME.hgs-new` and only then
// puts it in the folder's place, so a process killed at any moment leaves the old folder or the new one, never a
// mix. The temporary folder starts as a copy of the folder's current entries (hard links: no data is copied, and
// the files the writer replaces are written anew beside them by core/fs.h's atomic writes, never through a link),
// so what the writer does not touch is kept: a training run's config.json and checkpoints/.
//
// The swap: renameat2(RENAME_EXCHANGE) exchanges the two folders in one system call, then the old one (now under
// the temporary name) is removed. File systems without it: the folder is renamed to `.NAME.hgs-old`, the new one
// renamed in, the old removed; a kill between those two renames leaves the folder missing and both complete copies
// beside it, and the next write_folder_whole of that folder puts the old one back first. The folder is a new one
// afterwards: this process, if it works inside it, is moved to the same place in the new one; another process
// working there (a shell in out/) sees the old, removed folder until it changes folder (`cd .`).
#pragma once
#include <cstddef>
#include <filesystem>
#include <functional>

namespace hgs {
namespace fs = std::filesystem;

// A model folder holds tens of files (checkpoints included); a folder of more than this many entries is not
// mirrored and swapped (Model.save into a home folder would relink, and replace, all of it): an hgs::Error.
inline constexpr size_t kMaxFolderEntries = 10000;

// Calls write(tmp) to write the folder's new files into `tmp` (with core/fs.h's atomic writes), then makes `tmp`
// the folder `dir` (created when new; a symlink to a folder is followed). If `write` throws, `dir` is unchanged
// and the temporary folder removed. Refuses (hgs::Error naming the entry) a folder holding anything other than
// files, folders and symlinks, another file system mounted inside it, or more than kMaxFolderEntries entries.
void write_folder_whole(const fs::path& dir, const std::function<void(const fs::path& tmp)>& write);

}  // namespace hgs
