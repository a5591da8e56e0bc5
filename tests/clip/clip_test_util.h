// Helpers shared by the CLIP tests: reference arrays from tests/data/clip (written by
// tools/clip_reference/make_reference.py with PyTorch) and comparisons.
#pragma once
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "core/npy.h"

namespace hgs::test {

inline std::filesystem::path clip_data(const std::string& rel) {
  return std::filesystem::path(HGS_TEST_DATA) / "clip" / rel;
}

inline std::vector<float> ref_array(const std::string& rel, std::vector<size_t>* shape = nullptr) {
  NpyArray a = read_npy(clip_data(rel));
  if (shape) *shape = a.shape;
  return a.to_float();
}

// Largest |a - b| / (1 + |b|) over all elements; sizes must agree.
inline double max_rel_err(const std::vector<float>& a, const std::vector<float>& b) {
  EXPECT_EQ(a.size(), b.size());
  double m = 0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i)
    m = std::max(m, std::fabs(double(a[i]) - b[i]) / (1 + std::fabs(b[i])));
  return m;
}

}  // namespace hgs::test
