// Model PLY: exact round trip (all SH degrees, extra groups), layout compatible with 3DGS viewers, and
// one-line errors for missing properties, malformed headers, ascii and truncated bodies.
#include <gtest/gtest.h>

#include <fstream>
#include <functional>
#include <limits>
#include <random>

#include "core/error.h"
#include "core/fs.h"
#include "core/half.h"
#include "expect_error.h"
#include "model/ply.h"
#include "test_util.h"

namespace hgs {
namespace {

GaussianModel random_model(int n, int degree, unsigned seed) {
  GaussianModel m;
  m.sh_degree = degree;
  m.resize(n);
  std::mt19937 rng(seed);
  std::normal_distribution<float> nd;
  for (auto& f : m.fields())
    for (auto& v : *f.data) v = nd(rng);
  return m;
}

std::string read_header(const std::filesystem::path& p) {
  std::string s = read_file_text(p);
  return s.substr(0, s.find("end_header"));
}

TEST(Ply, RoundTripExactAllDegrees) {
  test::TempDir dir;
  for (int d = 0; d <= 3; ++d) {
    GaussianModel m = random_model(57, d, 10 + d);
    write_model_ply(dir / "m.ply", m);
    GaussianModel r = read_model_ply(dir / "m.ply");
    EXPECT_EQ(r.n, m.n);
    EXPECT_EQ(r.sh_degree, d);
    EXPECT_EQ(r.mean, m.mean);
    EXPECT_EQ(r.log_scale, m.log_scale);
    EXPECT_EQ(r.quat, m.quat);
    EXPECT_EQ(r.opacity_logit, m.opacity_logit);
    EXPECT_EQ(r.sh, m.sh);
    EXPECT_TRUE(r.extras.empty());
  }
}

TEST(Ply, RoundTripExtras) {
  test::TempDir dir;
  GaussianModel m = random_model(33, 3, 7);
  auto& q = m.add_extra("obj", 5);
  for (size_t i = 0; i < q.data.size(); ++i) q.data[i] = float(i) * 0.25f - 3.f;
  auto& z = m.add_extra("obj_id", 1);
  for (int i = 0; i < m.n; ++i) z.data[i] = float(i % 5);
  auto& f = m.add_extra("lang", 12);
  for (size_t i = 0; i < f.data.size(); ++i) f.data[i] = std::sin(float(i));
  write_model_ply(dir / "m.ply", m);
  std::string h = read_header(dir / "m.ply");
  EXPECT_NE(h.find("property float rot_3\nproperty float f_obj_0\n"), std::string::npos);
  EXPECT_NE(h.find("property float f_obj_4\nproperty float obj_id\nproperty float f_lang_0\n"), std::string::npos);
  GaussianModel r = read_model_ply(dir / "m.ply");
  ASSERT_EQ(r.extras.size(), 3u);
  for (int g = 0; g < 3; ++g) {
    EXPECT_EQ(r.extras[g].name, m.extras[g].name);
    EXPECT_EQ(r.extras[g].dim, m.extras[g].dim);
    EXPECT_EQ(r.extras[g].data, m.extras[g].data);
  }
  EXPECT_EQ(r.sh, m.sh);
}

TEST(Model, HalfPrecisionExtraGroup) {
  // A half-precision group is not a float field; resize, gather (growth and in-place compaction), validate,
  // row access and the PLY writer (float32, exact widening) all handle it.
  test::TempDir dir;
  GaussianModel m = random_model(6, 0, 3);
  auto& f = m.add_extra("lang", 10, 0.f, true);
  EXPECT_TRUE(f.data.empty());
  ASSERT_EQ(f.half.size(), 60u);
  for (size_t k = 0; k < 60; ++k) f.half[k] = float_to_half(float(k) * 0.5f - 7.f);  // exact in half
  EXPECT_EQ(m.fields().size(), 5u);                                                  // the base fields only
  m.validate("test");
  std::vector<float> row(10);
  m.find_extra("lang")->row(4, row.data());
  EXPECT_EQ(row[3], 43 * 0.5f - 7.f);
  EXPECT_EQ(m.find_extra("lang")->value(59), 59 * 0.5f - 7.f);
  m.gather({5, 0, 0, 2, 1, 3, 4});  // growth
  EXPECT_EQ(m.n, 7);
  EXPECT_EQ(m.find_extra("lang")->value(0), 50 * 0.5f - 7.f);
  EXPECT_EQ(m.find_extra("lang")->value(20), 0 * 0.5f - 7.f);
  const std::vector<float> before = m.find_extra("lang")->to_float();
  m.gather({1, 3, 6});  // pruning: in place
  EXPECT_EQ(m.n, 3);
  const std::vector<float> after = m.find_extra("lang")->to_float();
  for (int c = 0; c < 10; ++c) {
    EXPECT_EQ(after[c], before[10 + c]);
    EXPECT_EQ(after[10 + c], before[30 + c]);
    EXPECT_EQ(after[20 + c], before[60 + c]);
  }
  EXPECT_EQ(m.mean.size(), 9u);
  m.validate("test");
  write_model_ply(dir / "m.ply", m);
  GaussianModel r = read_model_ply(dir / "m.ply");
  ASSERT_EQ(r.extras.size(), 1u);
  EXPECT_FALSE(r.extras[0].f16);
  EXPECT_EQ(r.extras[0].data, after);
  m.find_extra("lang")->half.pop_back();
  EXPECT_THROW(m.validate("test"), Error);
}

TEST(Ply, StandardLayoutIsChannelMajor) {
  test::TempDir dir;
  GaussianModel m;
  m.sh_degree = 3;
  m.resize(1);
  for (int j = 0; j < 16; ++j)
    for (int c = 0; c < 3; ++c) m.sh[j * 3 + c] = float(100 * c + j);  // value encodes (coef, channel)
  m.mean = {1, 2, 3};
  write_model_ply(dir / "m.ply", m);
  std::string h = read_header(dir / "m.ply");
  const char* expect_prefix = "ply\nformat binary_little_endian 1.0\n";
  EXPECT_EQ(h.rfind(expect_prefix, 0), 0u);
  size_t props = 0;
  for (size_t p = h.find("property float"); p != std::string::npos; p = h.find("property float", p + 1)) ++props;
  EXPECT_EQ(props, 62u);  // 3 + 3 + 3 + 45 + 1 + 3 + 4
  EXPECT_LT(h.find("property float nz\nproperty float f_dc_0"), h.find("f_rest_0"));
  EXPECT_NE(h.find("property float f_rest_44\nproperty float opacity\nproperty float scale_0\nproperty float scale_1\n"
                   "property float scale_2\nproperty float rot_0"),
            std::string::npos);
  auto bytes = read_file_bytes(dir / "m.ply");
  size_t body = std::string(bytes.begin(), bytes.end()).find("end_header\n") + 11;
  ASSERT_EQ(bytes.size() - body, 62u * 4);
  std::vector<float> row(62);
  std::memcpy(row.data(), bytes.data() + body, 62 * 4);
  EXPECT_EQ(row[0], 1.f);
  EXPECT_EQ(row[6], 0.f);         // f_dc_0 = R of coefficient 0
  EXPECT_EQ(row[8], 200.f);       // f_dc_2 = B of coefficient 0
  EXPECT_EQ(row[9], 1.f);         // f_rest_0 = R of coefficient 1
  EXPECT_EQ(row[9 + 14], 15.f);   // f_rest_14 = R of coefficient 15
  EXPECT_EQ(row[9 + 15], 101.f);  // f_rest_15 = G of coefficient 1
  EXPECT_EQ(row[9 + 44], 215.f);  // f_rest_44 = B of coefficient 15
}

// Writes a PLY by hand with the given header properties (all float) and `n` rows of the given values.
void write_raw(const std::filesystem::path& p, const std::vector<std::string>& names, int n,
               const std::vector<float>& body, const std::string& format = "binary_little_endian 1.0") {
  std::string h = "ply\nformat " + format + "\nelement vertex " + std::to_string(n) + "\n";
  for (auto& nm : names) h += "property float " + nm + "\n";
  h += "end_header\n";
  std::ofstream f(p, std::ios::binary);
  f.write(h.data(), h.size());
  f.write(reinterpret_cast<const char*>(body.data()), body.size() * 4);
}

const std::vector<std::string> kMinimal = {"x",       "y",       "z",       "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
                                           "scale_0", "scale_1", "scale_2", "rot_0",  "rot_1",  "rot_2",  "rot_3"};

TEST(Ply, AnyOrderAndDegreeZero) {
  test::TempDir dir;
  std::vector<std::string> names(kMinimal.rbegin(), kMinimal.rend());  // reversed order
  std::vector<float> body;
  for (int i = 0; i < 2; ++i)
    for (size_t k = 0; k < names.size(); ++k) body.push_back(float(10 * i + k));
  write_raw(dir / "r.ply", names, 2, body);
  GaussianModel m = read_model_ply(dir / "r.ply");
  EXPECT_EQ(m.sh_degree, 0);
  ASSERT_EQ(m.n, 2);
  // rot_3 is the first property, x the last (index 13).
  EXPECT_EQ(m.mean[0], 13.f);
  EXPECT_EQ(m.mean[3], 23.f);
  EXPECT_EQ(m.quat[3], 0.f);
  EXPECT_EQ(m.quat[4 + 0], 13.f);       // rot_0 is at index 3 -> 10 + 3
  EXPECT_EQ(m.opacity_logit[1], 17.f);  // opacity is at reversed index 7
}

std::string error_of(const std::filesystem::path& p) {
  try {
    read_model_ply(p);
  } catch (const Error& e) {
    return e.what();
  }
  return "";
}

TEST(Ply, MissingProperty) {
  test::TempDir dir;
  auto names = kMinimal;
  names.erase(names.begin() + 8);  // scale_1
  write_raw(dir / "a.ply", names, 1, std::vector<float>(names.size(), 0.f));
  std::string e = error_of(dir / "a.ply");
  EXPECT_NE(e.find("a.ply"), std::string::npos) << e;
  EXPECT_NE(e.find("missing property 'scale_1'"), std::string::npos) << e;
  EXPECT_EQ(e.find('\n'), std::string::npos);
}

TEST(Ply, WrongRestCountAndGaps) {
  test::TempDir dir;
  auto names = kMinimal;
  for (int i = 0; i < 10; ++i) names.push_back("f_rest_" + std::to_string(i));
  write_raw(dir / "b.ply", names, 1, std::vector<float>(names.size(), 0.f));
  EXPECT_NE(error_of(dir / "b.ply").find("10 f_rest properties"), std::string::npos) << error_of(dir / "b.ply");
  names = kMinimal;
  names.push_back("f_obj_0");
  names.push_back("f_obj_2");
  write_raw(dir / "c.ply", names, 1, std::vector<float>(names.size(), 0.f));
  EXPECT_NE(error_of(dir / "c.ply").find("'obj' has 2 channels but no index 1"), std::string::npos)
      << error_of(dir / "c.ply");
}

TEST(Ply, MalformedHeaderAsciiTruncated) {
  test::TempDir dir;
  write_raw(dir / "asc.ply", kMinimal, 1, {}, "ascii 1.0");
  EXPECT_NE(error_of(dir / "asc.ply").find("ASCII PLY is not supported"), std::string::npos);
  write_raw(dir / "t.ply", kMinimal, 3, std::vector<float>(kMinimal.size() * 2 + 5, 0.f));
  EXPECT_NE(error_of(dir / "t.ply").find("truncated body"), std::string::npos) << error_of(dir / "t.ply");
  atomic_write_text(dir / "h.ply", "ply\nformat binary_little_endian 1.0\nelement vertex\nend_header\n");
  EXPECT_NE(error_of(dir / "h.ply").find("malformed element line"), std::string::npos) << error_of(dir / "h.ply");
  atomic_write_text(dir / "n.ply", "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n");
  EXPECT_NE(error_of(dir / "n.ply").find("not terminated by end_header"), std::string::npos);
  atomic_write_text(dir / "x.ply", "PK\x03\x04");
  EXPECT_NE(error_of(dir / "x.ply").find("not a PLY file"), std::string::npos);
  atomic_write_text(dir / "ty.ply",
                    "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty half x\nend_header\n");
  EXPECT_NE(error_of(dir / "ty.ply").find("unknown property type 'half'"), std::string::npos);
  EXPECT_NE(error_of(dir / "absent.ply").find("absent.ply"), std::string::npos);
}

// fuzz_ply (UBSan): a header with "element vertex 0.2" was read as 0 Gaussians, and the reader then formed
// `data() + c` on the empty arrays (an offset applied to a null pointer). Counts with trailing characters are
// refused; a model with no Gaussians (with an extra group too) reads back empty.
TEST(Ply, ZeroGaussiansAndCountsWithTrailingCharacters) {
  test::TempDir dir;
  write_raw(dir / "f.ply", kMinimal, 0, {}, "binary_little_endian 1.0");
  std::string text = read_file_text(dir / "f.ply");
  const size_t at = text.find("element vertex 0");
  ASSERT_NE(at, std::string::npos);
  text.insert(at + 16, ".2");
  atomic_write_text(dir / "g.ply", text);
  EXPECT_NE(error_of(dir / "g.ply").find("malformed element line 'element vertex 0.2'"), std::string::npos)
      << error_of(dir / "g.ply");
  GaussianModel m;
  m.sh_degree = 1;
  m.resize(0);
  m.add_extra("obj", 3);
  write_model_ply(dir / "empty.ply", m);
  const GaussianModel r = read_model_ply(dir / "empty.ply");
  EXPECT_EQ(r.n, 0);
  EXPECT_EQ(r.sh_degree, 1);
  ASSERT_NE(r.find_extra("obj"), nullptr);
  EXPECT_EQ(r.find_extra("obj")->dim, 3);
}

TEST(Ply, WriteIsAtomicAndRejectsBadGroupName) {
  test::TempDir dir;
  GaussianModel m = random_model(4, 1, 3);
  m.add_extra("f_bad", 2);
  EXPECT_THROW(write_model_ply(dir / "m.ply", m), Error);
  EXPECT_FALSE(std::filesystem::exists(dir / "m.ply"));
  EXPECT_TRUE(std::filesystem::is_empty(dir.path));
}

TEST(Ply, NonFiniteValuesAreRefusedAtWriteNamingTheArray) {
  // read_model_ply refuses them, so a saved file could not be loaded again (issue 60): refused before writing.
  test::TempDir dir;
  GaussianModel m = random_model(20, 1, 3);
  auto& f = m.add_extra("lang", 4, 0.f, true);  // half storage: checked too
  (void)f;
  write_model_ply(dir / "ok.ply", m);
  struct Case {
    std::function<void(GaussianModel&)> poison;
    std::string named;
  };
  const float inf = std::numeric_limits<float>::infinity(), nan = std::numeric_limits<float>::quiet_NaN();
  const std::vector<Case> cases = {
      {[&](GaussianModel& g) { g.mean[3 * 7 + 1] = nan; },
       "means holds 1 NaN or infinite value (the first at Gaussian 7)"},
      {[&](GaussianModel& g) { g.log_scale[5] = inf; }, "log_scales holds 1"},
      {[&](GaussianModel& g) { g.quat[4 * 19] = -inf; },
       "rotations holds 1 NaN or infinite value (the first at Gaussian 19)"},
      {[&](GaussianModel& g) { g.opacity_logit[2] = g.opacity_logit[3] = nan; },
       "opacity_logits holds 2 NaN or infinite values (the first at Gaussian 2)"},
      {[&](GaussianModel& g) { g.sh[12 * 4 * 3 + 5] = nan; },
       "sh holds 1 NaN or infinite value (the first at Gaussian 12)"},
      {[&](GaussianModel& g) { g.extras[0].half[4 * 9 + 2] = 0x7C00; },
       "extras['lang'] holds 1 NaN or infinite value (the first at Gaussian 9)"},
  };
  for (const Case& c : cases) {
    GaussianModel bad = m;
    c.poison(bad);
    EXPECT_FILE_ERROR(write_model_ply(dir / "bad.ply", bad), dir / "bad.ply", c.named);
    EXPECT_FALSE(std::filesystem::exists(dir / "bad.ply"));
  }
}

}  // namespace
}  // namespace hgs
