#include <gtest/gtest.h>

#include <cstring>
#include <fstream>

#include "core/error.h"
#include "core/fs.h"
#include "core/half.h"
#include "core/npy.h"
#include "test_util.h"

using namespace hgs;

namespace {
NpyArray make(DType t, std::vector<size_t> shape) {
  NpyArray a;
  a.dtype = t;
  a.shape = shape;
  a.data.resize(a.size() * dtype_size(t));
  for (size_t i = 0; i < a.data.size(); ++i) a.data[i] = static_cast<uint8_t>((i * 37 + 11) & 0xff);
  if (t == DType::F16)  // keep values finite
    for (size_t i = 0; i < a.size(); ++i) a.as<uint16_t>()[i] = float_to_half(0.25f * float(i) - 3.f);
  if (t == DType::F32)
    for (size_t i = 0; i < a.size(); ++i) a.as<float>()[i] = 1.5f * float(i) - 7.f;
  return a;
}
}  // namespace

TEST(Npy, RoundTripEveryDtype) {
  test::TempDir tmp;
  for (DType t : {DType::F16, DType::F32, DType::U8, DType::U16, DType::I32}) {
    for (auto shape : std::vector<std::vector<size_t>>{{7}, {3, 5}, {2, 3, 4}, {0, 4}}) {
      NpyArray a = make(t, shape);
      auto p = tmp / "a.npy";
      write_npy(p, a);
      NpyArray b = read_npy(p);
      EXPECT_EQ(b.dtype, a.dtype);
      EXPECT_EQ(b.shape, a.shape);
      EXPECT_EQ(b.data, a.data);
      // header is 64-byte aligned as NumPy writes it
      auto bytes = read_file_bytes(p);
      EXPECT_EQ((bytes.size() - a.data.size()) % 64, 0u);
    }
  }
}

TEST(Npy, ToFloatConverts) {
  NpyArray a = make(DType::F16, {4});
  auto f = a.to_float();
  EXPECT_FLOAT_EQ(f[0], -3.f);
  EXPECT_FLOAT_EQ(f[3], -2.25f);
  NpyArray b = make(DType::I32, {2});
  b.as<int32_t>()[0] = -5;
  EXPECT_FLOAT_EQ(b.to_float()[0], -5.f);
}

TEST(Npy, ParsesNumpyStyleHeaders) {
  // A header as numpy 1.x writes it for np.zeros((2,3), np.float32), and a version-2 header.
  std::string h = "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }";
  h += std::string(64 - (10 + h.size() + 1) % 64, ' ') + "\n";
  std::vector<uint8_t> f = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, uint8_t(h.size()), 0};
  // GCC 12 false positive: -Warray-bounds / -Wstringop-overread take the vector's first 10 bytes for the whole
  // buffer of the insert.
#ifndef __clang__  // warnings clang does not have
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Warray-bounds"
#pragma GCC diagnostic ignored "-Wstringop-overread"
#endif
  f.insert(f.end(), h.begin(), h.end());
#ifndef __clang__
#pragma GCC diagnostic pop
#endif
  f.resize(f.size() + 24, 0);
  NpyArray a = parse_npy(f.data(), f.size(), "x.npy");
  EXPECT_EQ(a.shape, (std::vector<size_t>{2, 3}));
  std::vector<uint8_t> g = {0x93, 'N', 'U', 'M', 'P', 'Y', 2, 0, uint8_t(h.size()), 0, 0, 0};
  g.insert(g.end(), h.begin(), h.end());
  g.resize(g.size() + 24, 0);
  EXPECT_EQ(parse_npy(g.data(), g.size(), "y.npy").size(), 6u);
}

namespace {
std::vector<uint8_t> with_header(const std::string& dict, size_t body) {
  std::string h = dict + "\n";
  std::vector<uint8_t> f = {0x93, 'N', 'U', 'M', 'P', 'Y', 1, 0, uint8_t(h.size()), 0};
  // GCC 12 false positive: -Warray-bounds / -Wstringop-overread take the vector's first 10 bytes for the whole
  // buffer of the insert.
#ifndef __clang__  // warnings clang does not have
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Warray-bounds"
#pragma GCC diagnostic ignored "-Wstringop-overread"
#endif
  f.insert(f.end(), h.begin(), h.end());
#ifndef __clang__
#pragma GCC diagnostic pop
#endif
  f.resize(f.size() + body, 0);
  return f;
}
void expect_error(const std::vector<uint8_t>& f, const std::string& needle) {
  try {
    parse_npy(f.data(), f.size(), "bad.npy");
    FAIL() << "expected an error containing '" << needle << "'";
  } catch (const Error& e) {
    std::string m = e.what();
    EXPECT_NE(m.find("bad.npy"), std::string::npos) << m;
    EXPECT_NE(m.find(needle), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos) << "error must be one line: " << m;
  }
}
}  // namespace

TEST(Npy, RejectsBadInput) {
  expect_error({'n', 'o', 't', ' ', 'n', 'p', 'y', 0, 0, 0, 0}, "bad magic");
  expect_error(with_header("{'descr': '<f8', 'fortran_order': False, 'shape': (2,), }", 16),
               "unsupported NPY dtype '<f8'");
  expect_error(with_header("{'descr': '>f4', 'fortran_order': False, 'shape': (2,), }", 8), "unsupported NPY dtype");
  expect_error(with_header("{'descr': '<f4', 'fortran_order': True, 'shape': (2, 2), }", 16), "Fortran");
  expect_error(with_header("{'descr': '<f4', 'fortran_order': False, 'shape': (4,), }", 8), "truncated NPY body");
  expect_error(with_header("{'descr': '<f4', 'fortran_order': False }", 8), "no 'shape'");
  expect_error(with_header("{'descr': '<f4', 'fortran_order': False, 'shape': (2, x), }", 8), "malformed NPY shape");
  auto trunc = with_header("{'descr': '<f4', 'fortran_order': False, 'shape': (2,), }", 8);
  trunc.resize(20);
  expect_error(trunc, "truncated NPY header");
}

TEST(Npy, MissingFileIsAClearError) {
  try {
    read_npy("/nonexistent/x.npy");
    FAIL();
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("/nonexistent/x.npy: file not found"), std::string::npos);
  }
}
