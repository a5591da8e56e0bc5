// safetensors reader: round trips in F32/F16/BF16 and one-line errors for malformed files.
#include <gtest/gtest.h>

#include <cstring>
#include <fstream>

#include "core/error.h"
#include "core/half.h"
#include "nn/safetensors.h"
#include "test_util.h"

using namespace hgs;
using namespace hgs::nn;

namespace {

void write_raw(const std::filesystem::path& p, const std::string& header, size_t data_bytes) {
  std::ofstream f(p, std::ios::binary);
  uint64_t n = header.size();
  f.write(reinterpret_cast<const char*>(&n), 8);
  f << header;
  std::string zeros(data_bytes, '\0');
  f << zeros;
}

}  // namespace

TEST(SafeTensors, RoundTripAllDtypes) {
  test::TempDir t;
  std::vector<float> a(2 * 3), b(5);
  for (size_t i = 0; i < a.size(); ++i) a[i] = 0.37f * float(i) - 1.1f;
  for (size_t i = 0; i < b.size(); ++i) b[i] = 1000.f / (i + 1);
  for (StDType dt : {StDType::F32, StDType::F16, StDType::BF16}) {
    auto p = t / "m.safetensors";
    write_safetensors(p, {{"x.weight", {2, 3}, a.data()}, {"y", {5}, b.data()}}, dt, {{"k", "v"}});
    SafeTensors st(p);
    EXPECT_EQ(st.metadata().at("k"), "v");
    EXPECT_EQ(st.info("x.weight").shape, (std::vector<int64_t>{2, 3}));
    auto ra = st.to_float("x.weight", {2, 3}), rb = st.to_float("y", {-1});
    for (size_t i = 0; i < a.size(); ++i) {
      float expect = dt == StDType::F32 ? a[i] : dt == StDType::F16 ? half_to_float(float_to_half(a[i])) : 0.f;
      if (dt == StDType::BF16) {
        EXPECT_NEAR(ra[i], a[i], std::fabs(a[i]) / 128 + 1e-30);
        uint32_t u;
        std::memcpy(&u, &ra[i], 4);
        EXPECT_EQ(u & 0xFFFF, 0u);  // exactly representable in bf16
      } else {
        EXPECT_EQ(ra[i], expect);
      }
    }
    EXPECT_NEAR(rb[4], 200.f, dt == StDType::F32 ? 0 : 1.f);
  }
}

TEST(SafeTensors, MalformedFilesGiveClearErrors) {
  test::TempDir t;
  auto p = t / "bad.safetensors";
  auto load = [&] { SafeTensors st(p); };

  EXPECT_NE(test::error_of([&] { SafeTensors st(t / "absent.safetensors"); }).find("file not found"),
            std::string::npos);

  {
    std::ofstream f(p, std::ios::binary);
    f << "abc";
  }
  EXPECT_NE(test::error_of(load).find("truncated"), std::string::npos);

  write_raw(p, "{\"a\": {\"dtype\": \"F32\", \"shape\": [2], \"data_offsets\": [0, 8]}}", 8);
  {
    std::fstream f(p, std::ios::binary | std::ios::in | std::ios::out);
    uint64_t n = 1u << 30;
    f.write(reinterpret_cast<char*>(&n), 8);
  }
  EXPECT_NE(test::error_of(load).find("header length"), std::string::npos);

  write_raw(p, "{not json", 0);
  EXPECT_NE(test::error_of(load).find("not valid JSON"), std::string::npos);

  write_raw(p, "{\"a\": {\"dtype\": \"F32\", \"shape\": [4], \"data_offsets\": [0, 16]}}", 8);  // truncated data
  std::string e = test::error_of(load);
  EXPECT_NE(e.find("'a'"), std::string::npos) << e;
  EXPECT_NE(e.find("truncated"), std::string::npos) << e;
  EXPECT_NE(e.find(p.string()), std::string::npos) << e;

  write_raw(p, "{\"a\": {\"dtype\": \"F32\", \"shape\": [4], \"data_offsets\": [8, 0]}}", 16);
  EXPECT_NE(test::error_of(load).find("wrong order"), std::string::npos);

  write_raw(p, "{\"a\": {\"dtype\": \"F32\", \"shape\": [3], \"data_offsets\": [0, 16]}}", 16);
  EXPECT_NE(test::error_of(load).find("should take 12 bytes"), std::string::npos);

  write_raw(p, "{\"a\": {\"dtype\": \"F32\", \"shape\": [3]}}", 16);
  EXPECT_NE(test::error_of(load).find("malformed header entry"), std::string::npos);

  write_raw(p, "{\"a\": {\"dtype\": \"I64\", \"shape\": [2], \"data_offsets\": [0, 16]}}", 16);
  SafeTensors st(p);
  e = test::error_of([&] { st.to_float("a"); });
  EXPECT_NE(e.find("I64"), std::string::npos) << e;
  e = test::error_of([&] { st.to_float("missing.weight"); });
  EXPECT_NE(e.find("missing tensor 'missing.weight'"), std::string::npos) << e;

  write_raw(p, "{\"a\": {\"dtype\": \"F32\", \"shape\": [2, 2], \"data_offsets\": [0, 16]}}", 16);
  SafeTensors st2(p);
  e = test::error_of([&] { st2.to_float("a", {4, 1}); });
  EXPECT_NE(e.find("'a' has shape [2, 2] but [4, 1] was expected"), std::string::npos) << e;
  EXPECT_NO_THROW(st2.to_float("a", {2, -1}));
}
