// Helpers shared by the SAM tests: the tiny model and reference arrays of tests/data/sam (written by
// tools/sam_reference/make_reference.py with PyTorch) and comparisons.
#pragma once
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <string>
#include <vector>

#include "core/image.h"
#include "core/npy.h"
#include "sam/model.h"

namespace hgs::test {

inline std::filesystem::path sam_data(const std::string& rel) { return std::filesystem::path(HGS_TEST_DATA) / "sam" / rel; }

inline std::vector<float> sam_ref(const std::string& rel, std::vector<size_t>* shape = nullptr) {
  NpyArray a = read_npy(sam_data(rel));
  if (shape) *shape = a.shape;
  return a.to_float();
}

// The fixture image: uint8 [H, W, 3] / 255.
inline Image sam_image() {
  NpyArray a = read_npy(sam_data("image.npy"));
  Image img(int(a.shape[1]), int(a.shape[0]), 3);
  const uint8_t* p = a.as<uint8_t>();
  for (size_t i = 0; i < img.px.size(); ++i) img.px[i] = float(p[i]) / 255.f;
  return img;
}

inline const sam::SamModel& tiny_sam() {
  static const sam::SamModel m = sam::SamModel::load(sam_data("tiny_sam.safetensors"));
  return m;
}

// Largest |a - b| / (1 + |b|) over all elements; sizes must agree.
inline double max_rel_err(const std::vector<float>& a, const std::vector<float>& b) {
  EXPECT_EQ(a.size(), b.size());
  double m = 0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) m = std::max(m, std::fabs(double(a[i]) - b[i]) / (1 + std::fabs(b[i])));
  return m;
}

}  // namespace hgs::test
