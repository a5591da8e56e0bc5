// Inputs found by fuzzing hgs masks import's readers (fuzz/fuzz_sam_masks.cpp, fuzz/fuzz_langsplat.cpp;
// docs/reliability.md), each failing before its fix, now a one-line hgs::Error naming the file.
#include <gtest/gtest.h>

#include <vector>

#include "core/error.h"
#include "core/fs.h"
#include "core/npy.h"
#include "expect_error.h"
#include "masks/sources.h"
#include "test_util.h"

using namespace hgs;

// fuzz_sam_masks: a number too large for a double ("183e0666...") made nlohmann-json throw out_of_range, which
// escaped the reader (only parse_error was caught).
TEST(FuzzRegressions, SamJsonNumberOverflow) {
  test::TempDir t;
  const auto f = t / "frame_00001.json";
  atomic_write_text(f, R"([{"area": 4, "bbox": [0, 6, 32, 183e0666666666666666666666666666666666666666666666661]}])");
  EXPECT_FILE_ERROR(masks::read_sam_json(f, 32, 24), f, "invalid JSON");
}

// fuzz_langsplat (UBSan): a float mask index of 1.1e20 in _s.npy was cast to int64 (float-cast-overflow).
TEST(FuzzRegressions, LangSplatIndexOutOfInt64Range) {
  test::TempDir t;
  const auto f = t / "frame_00001_s.npy";
  const std::vector<float> v = {0.f, 1.1e20f, -1.f};
  write_npy(f, make_npy_f32({3}, v.data()));
  std::vector<size_t> shape;
  EXPECT_FILE_ERROR(masks::read_npy_integers(f, shape), f, "out of range");
}
