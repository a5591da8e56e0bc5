// Inputs found by fuzzing the 3D-OVS label loader (fuzz/fuzz_ovs_segmentations.cpp; docs/reliability.md), each
// failing before its fix, now a one-line hgs::Error naming the file.
#include <gtest/gtest.h>

#include <string>

#include "core/fs.h"
#include "eval/labels.h"
#include "expect_error.h"
#include "test_util.h"

using namespace hgs;
namespace fs = std::filesystem;

// fuzz_ovs_segmentations: a class name longer than the file-name limit made the class mask's path throw
// std::filesystem_error ("File name too long") out of load_3dovs_view; a control character made a multi-line
// message.
TEST(FuzzRegressions, OvsClassNameTooLongOrWithControlCharacters) {
  for (const std::string& bad : {std::string(300, 'P'), std::string("mug\rcup")}) {
    test::TempDir t;
    ensure_dir(t / "segmentations" / "0");
    atomic_write_text(t / "segmentations" / "classes.txt", "table\n" + bad + "\n");
    EXPECT_FILE_ERROR(eval::open_3dovs_labels(t.path), t / "segmentations" / "classes.txt",
                      bad.size() > 200 ? "too long" : "control characters");
  }
}
