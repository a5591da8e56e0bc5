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

// fuzz_langsplat: the seg map reader had its own NPY shape parser, which took any digits inside the tuple and
// let std::stoull throw out_of_range on a 23-digit dimension (and could overflow the element count); it now
// uses core's checked parse_npy_shape. (The fuzz input is fuzz/corpus/langsplat/finding_shape_not_digits.)
TEST(FuzzRegressions, LangSplatShapeDimensionTooLarge) {
  test::TempDir t;
  auto npy = [&](const std::string& shape) {
    std::string h = "{'descr': '<f4', 'fortran_order': False, 'shape': (" + shape + "), }";
    h.resize(118, ' ');
    h += '\n';
    std::string b = "\x93NUMPY\x01";
    b += '\0';
    b += char(h.size() & 0xFF);
    b += char(h.size() >> 8);
    return b + h;
  };
  const auto f = t / "frame_00001_s.npy";
  std::vector<size_t> shape;
  atomic_write_text(f, npy("99999999999999999999999, 2"));
  EXPECT_FILE_ERROR(masks::read_npy_integers(f, shape), f, "too large");
  atomic_write_text(f, npy("4294967296, 4294967296, 4"));  // the element count overflows 64 bits
  EXPECT_FILE_ERROR(masks::read_npy_integers(f, shape), f, "too large");
  atomic_write_text(f, npy("4,\xe0\xcd"
                           "6, 3"));  // not digits
  EXPECT_FILE_ERROR(masks::read_npy_integers(f, shape), f, "malformed NPY shape");
}
