// write_folder_whole (core/folder.h): a folder written as one change; what the writer does not replace is kept;
// a failing writer leaves the folder as it was; leftovers of a killed write are cleaned up.
#include <gtest/gtest.h>

#include <sys/stat.h>

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <stdexcept>

#include "core/error.h"
#include "core/folder.h"
#include "core/fs.h"
#include "test_util.h"

using namespace hgs;
namespace fs = std::filesystem;

namespace {
std::vector<std::string> names_in(const fs::path& dir) {
  std::vector<std::string> n;
  for (const auto& e : fs::recursive_directory_iterator(dir)) n.push_back(fs::relative(e.path(), dir).string());
  std::sort(n.begin(), n.end());
  return n;
}
}  // namespace

TEST(FolderWhole, NewFolderAppearsWithEveryFile) {
  test::TempDir tmp;
  write_folder_whole(tmp / "out", [](const fs::path& t) {
    EXPECT_FALSE(fs::exists(t.parent_path() / "out"));  // nothing under the name while it is written
    atomic_write_text(t / "a.txt", "a\n");
    atomic_write_text(t / "b.txt", "b\n");
  });
  EXPECT_EQ(names_in(tmp / "out"), (std::vector<std::string>{"a.txt", "b.txt"}));
  EXPECT_EQ(names_in(tmp.path), (std::vector<std::string>{"out", "out/a.txt", "out/b.txt"}));  // no temp left
}

TEST(FolderWhole, ExistingFolderKeepsWhatTheWriterDoesNotReplace) {
  test::TempDir tmp;
  const fs::path out = tmp / "out";
  fs::create_directories(out / "checkpoints");
  atomic_write_text(out / "config.json", "{}\n");
  atomic_write_text(out / "checkpoints" / "iter_8.ckpt", "ckpt\n");
  atomic_write_text(out / "point_cloud.ply", "old\n");
  fs::create_symlink("config.json", out / "link");
  ::chmod(out.c_str(), 0750);
  write_folder_whole(out.string() + "/", [](const fs::path& t) {
    EXPECT_EQ(read_file_text(t / "point_cloud.ply"), "old\n");  // the old files are there to be replaced
    atomic_write_text(t / "point_cloud.ply", "new\n");
    atomic_write_text(t / "train_stats.json", "{}\n");
  });
  EXPECT_EQ(read_file_text(out / "point_cloud.ply"), "new\n");
  EXPECT_EQ(read_file_text(out / "checkpoints" / "iter_8.ckpt"), "ckpt\n");
  EXPECT_EQ(read_file_text(out / "config.json"), "{}\n");
  EXPECT_EQ(read_file_text(out / "train_stats.json"), "{}\n");
  EXPECT_TRUE(fs::is_symlink(out / "link"));
  EXPECT_EQ(fs::status(out).permissions() & fs::perms::all, fs::perms(0750));
  EXPECT_EQ(names_in(tmp.path).size(), 7u);  // out and its 6 entries (checkpoints/ and its file): no temp folder
}

TEST(FolderWhole, FailingWriterLeavesTheFolderAsItWas) {
  // What a second Ctrl-C or a full disk during a model save did: point_cloud.ply written, then the rest missing.
  test::TempDir tmp;
  const fs::path out = tmp / "out";
  fs::create_directories(out);
  atomic_write_text(out / "point_cloud.ply", "old\n");
  EXPECT_THROW(write_folder_whole(out,
                                  [](const fs::path& t) {
                                    atomic_write_text(t / "point_cloud.ply", "new\n");
                                    throw Error("disk full");
                                  }),
               Error);
  EXPECT_EQ(read_file_text(out / "point_cloud.ply"), "old\n");
  EXPECT_EQ(names_in(tmp.path), (std::vector<std::string>{"out", "out/point_cloud.ply"}));
  EXPECT_THROW(write_folder_whole(tmp / "new", [](const fs::path&) { throw std::runtime_error("x"); }),
               std::runtime_error);
  EXPECT_FALSE(fs::exists(tmp / "new"));
}

TEST(FolderWhole, LeftoversOfAKilledWriteAreCleanedUp) {
  test::TempDir tmp;
  const fs::path out = tmp / "out";
  // Killed while writing the temporary folder: a partial .out.hgs-new.
  fs::create_directories(tmp / ".out.hgs-new");
  atomic_write_text(tmp / ".out.hgs-new" / "point_cloud.ply", "partial");
  // Killed between the two renames of the fallback swap: the folder missing, its old copy beside it.
  fs::create_directories(tmp / ".out.hgs-old");
  atomic_write_text(tmp / ".out.hgs-old" / "config.json", "kept\n");
  write_folder_whole(out, [](const fs::path& t) { atomic_write_text(t / "point_cloud.ply", "new\n"); });
  EXPECT_EQ(names_in(tmp.path), (std::vector<std::string>{"out", "out/config.json", "out/point_cloud.ply"}));
  EXPECT_EQ(read_file_text(out / "config.json"), "kept\n");
}

TEST(FolderWhole, RefusesAFileAndOddEntriesWithOneLine) {
  test::TempDir tmp;
  atomic_write_text(tmp / "file", "x");
  const std::string e1 = test::error_of([&] { write_folder_whole(tmp / "file", [](const fs::path&) {}); });
  EXPECT_NE(e1.find("file: exists and is not a folder"), std::string::npos) << e1;
  fs::create_directories(tmp / "out");
  ASSERT_EQ(::mkfifo((tmp / "out" / "pipe").c_str(), 0600), 0);
  const std::string e2 = test::error_of([&] { write_folder_whole(tmp / "out", [](const fs::path&) {}); });
  EXPECT_NE(e2.find("pipe: not a file or folder"), std::string::npos) << e2;
  EXPECT_TRUE(fs::exists(tmp / "out" / "pipe"));
  EXPECT_EQ(e2.find('\n'), std::string::npos);
}

TEST(FolderWhole, ProcessWorkingInsideTheFolderMovesToTheNewOne) {
  // Model.save(".") or `hgs train --out .`: the process's current folder is the one replaced.
  test::TempDir tmp;
  const fs::path out = tmp / "out";
  fs::create_directories(out / "sub");
  const fs::path before = fs::current_path();
  fs::current_path(out / "sub");
  try {
    write_folder_whole(fs::path(".."), [](const fs::path& t) { atomic_write_text(t / "new.txt", "n\n"); });
    EXPECT_TRUE(fs::exists("../new.txt"));  // relative paths still work: we are in the new folder
    EXPECT_TRUE(fs::equivalent(fs::current_path(), out / "sub"));
  } catch (...) {
    fs::current_path(before);
    throw;
  }
  fs::current_path(before);
  EXPECT_EQ(read_file_text(out / "new.txt"), "n\n");
}

TEST(FolderWhole, RefusesToMirrorAHugeFolder) {
  // Not a model folder (a home folder, say): refused before anything is linked or written.
  test::TempDir tmp;
  const fs::path out = tmp / "out";
  fs::create_directories(out / "many");
  for (size_t i = 0; i <= kMaxFolderEntries; ++i) std::ofstream(out / "many" / std::to_string(i)).put('x');
  const std::string e =
      test::error_of([&] { write_folder_whole(out, [](const fs::path& t) { atomic_write_text(t / "a", "a"); }); });
  EXPECT_NE(e.find("holds more than 10000 files and folders"), std::string::npos) << e;
  EXPECT_FALSE(fs::exists(out / "a"));
  EXPECT_EQ(std::distance(fs::directory_iterator(tmp.path), fs::directory_iterator()), 1);  // no temporary folder
}
