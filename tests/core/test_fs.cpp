// atomic_write: new files, replacements, and the complete copy a kill between link and rename may leave.
#include <gtest/gtest.h>

#include <filesystem>

#include "core/error.h"
#include "core/fs.h"
#include "test_util.h"

using namespace hgs;
namespace fs = std::filesystem;

namespace {
std::vector<std::string> names_in(const fs::path& dir) {
  std::vector<std::string> n;
  for (const auto& e : fs::directory_iterator(dir)) n.push_back(e.path().filename().string());
  std::sort(n.begin(), n.end());
  return n;
}
}  // namespace

TEST(AtomicWrite, CreatesAndReplacesLeavingOnlyTheOutput) {
  test::TempDir tmp;
  atomic_write_text(tmp / "a.txt", "first\n");
  EXPECT_EQ(read_file_text(tmp / "a.txt"), "first\n");
  atomic_write_text(tmp / "a.txt", "second, longer\n");
  EXPECT_EQ(read_file_text(tmp / "a.txt"), "second, longer\n");
  EXPECT_EQ(names_in(tmp.path), std::vector<std::string>{"a.txt"});
}

TEST(AtomicWrite, StaleReplaceCopyFromAKilledRunIsRemovedByTheNextWrite) {
  test::TempDir tmp;
  atomic_write_text(tmp / "a.txt", "old\n");
  // What a kill between linkat and rename leaves: a complete copy under the fixed replacement name.
  atomic_write_text(tmp / (std::string("a.txt") + kReplaceSuffix), "stale\n");
  ASSERT_EQ(names_in(tmp.path).size(), 2u);
  atomic_write_text(tmp / "a.txt", "new\n");
  EXPECT_EQ(read_file_text(tmp / "a.txt"), "new\n");
  EXPECT_EQ(names_in(tmp.path), std::vector<std::string>{"a.txt"});
}

TEST(AtomicWrite, WriterErrorLeavesNothing) {
  test::TempDir tmp;
  EXPECT_THROW(atomic_write(tmp / "b.bin", [](const fs::path&) { throw Error("writer failed"); }), Error);
  EXPECT_TRUE(names_in(tmp.path).empty());
}
