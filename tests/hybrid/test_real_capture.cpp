// A real capture: ../shared/data/goldcape (82 views of one object, real foreground masks; its language inputs
// are simulated, see its README). The hybrid model trained on it (8x downscaled, short schedule) must give the
// object's mask on the 11 held-out views against the real masks in object mode, and in pixel mode (LERF
// relevancy of the rendered language map) too: with one foreground object eq. 10 has no negative, and without
// the background as an SCL class (config.h scl_background, "auto") f is never trained and the relevancy inside
// the cape is noise.
#include <gtest/gtest.h>

#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "test_util.h"

using namespace hgs;

namespace {

// {mode: {"mIoU", "mBIoU"}} of an `hgs eval` report.json.
std::map<std::string, std::pair<double, double>> read_report(const std::filesystem::path& p) {
  std::map<std::string, std::pair<double, double>> out;
  const auto j = nlohmann::json::parse(read_file_text(p));
  for (const auto& r : j.at("reports"))
    out[r.at("mode").get<std::string>()] = {r.at("summary").at("mIoU").get<double>(),
                                            r.at("summary").at("mBIoU").get<double>()};
  return out;
}

}  // namespace

TEST(RealCapture, GoldCapeObjectAndPixelMasksMatchTheRealMasks) {
  HGS_REQUIRE_SHARED(scene, "goldcape");
  test::TempDir tmp;
  const std::string s = scene.string(), m = (tmp / "m").string();
  auto r = test::run_hgs("train " + s + " --downscale 8 --iters 600 --out " + m + " --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = test::run_hgs("eval " + s + " " + m + " --downscale 8 --protocol instances --no-png --quiet --out " + m +
                    "/report.json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto rep = read_report(tmp / "m" / "report.json");
  ASSERT_TRUE(rep.count("object") && rep.count("pixel"));
  // Measured 97.1 / 73.4 (object) and 77.5 / 24.9 (pixel); with --scl-background off 97.1 / 73.5 and 1.2 / 1.9.
  EXPECT_GT(rep.at("object").first, 0.93);
  EXPECT_GT(rep.at("object").second, 0.60);
  EXPECT_GT(rep.at("pixel").first, 0.60);
}
