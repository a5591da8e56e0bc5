// `hgs ablate` through the CLI on a tiny synthetic scene: rows x scenes x seeds with two protocols and both
// modes (pixel mode with the paper's language map beside the default rule), mean and sample standard deviation per
// row, paired differences clustered by scene, the eq. 15 row, and an interrupted ablation continuing from the runs
// already on disk. The interval arithmetic itself: tests/eval/test_paired_stats.cpp.
#include <gtest/gtest.h>

#include <cmath>
#include <map>
#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "test_util.h"

using namespace hgs;
namespace fs = std::filesystem;

TEST(AblateCli, RowsSeedsProtocolsModesAndResume) {
  test::TempDir tmp;
  const std::string s = (tmp / "s").string(), out = (tmp / "a").string();
  auto r = test::run_hgs("synth --world simple --out " + s +
                         " --views 16 --width 96 --height 72 --objects 3 --points 2000 "
                         "--noise medium --feature-dim 16 --supersample 1 --seed 4 --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string cmd =
      "ablate " + s + " --out " + out +
      " --iters 30 --rows ends --eq15-row --seeds 2 --protocol instances,3d-ovs --mode both --quiet";
  r = test::run_hgs(cmd);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto j = nlohmann::json::parse(read_file_text(tmp / "a" / "ablation.json"));
  ASSERT_EQ(j["summary"].size(), 3u);  // all-off, full, full with eq. 15 alone
  EXPECT_EQ(j["summary"][2]["lambda_rgb"].get<double>(), 0.0);
  EXPECT_EQ(j["summary"][1]["lambda_rgb"].get<double>(), 1.0);
  EXPECT_EQ(j["runs"].size(), 6u);  // 3 rows x 2 seeds
  for (const auto& row : j["summary"]) {
    for (const char* key : {"instances/object", "instances/pixel", "instances/pixel-paper-map", "3d-ovs/object",
                            "3d-ovs/pixel", "3d-ovs/pixel-paper-map"}) {
      ASSERT_TRUE(row["results"].contains(key)) << row["row"] << " " << key;
      const auto& k = row["results"][key];
      EXPECT_EQ(k["runs"], 2);
      ASSERT_TRUE(k["miou_mean"].is_number()) << key;
      ASSERT_TRUE(k["miou_std"].is_number()) << key;
      // The summary is the mean and sample std of the two runs' values.
      std::vector<double> v;
      for (const auto& run : j["runs"])
        if (run["row"] == row["row"]) v.push_back(run["run"]["results"][key]["miou"].get<double>());
      ASSERT_EQ(v.size(), 2u);
      EXPECT_NEAR(k["miou_mean"].get<double>(), (v[0] + v[1]) / 2, 1e-12);
      EXPECT_NEAR(k["miou_std"].get<double>(), std::abs(v[0] - v[1]) / std::sqrt(2.0), 1e-12);
    }
  }
  // Paired differences: the full row minus all-off, per seed, averaged over the seeds of the one scene; clustered
  // by scene, one scene gives no interval (n = 1 scene, not 2 runs).
  for (const char* key : {"instances/object", "3d-ovs/pixel"}) {
    std::map<uint64_t, double> full, off;
    for (const auto& run : j["runs"]) {
      const double v = run["run"]["results"][key]["miou"].get<double>();
      if (run["row"] == "of1_scl1_bro1") full[run["seed"].get<uint64_t>()] = v;
      if (run["row"] == "of0_scl0_bro0") off[run["seed"].get<uint64_t>()] = v;
    }
    ASSERT_EQ(full.size(), 2u);
    std::vector<double> d;
    for (auto [seed, v] : full) d.push_back(v - off.at(seed));
    const auto& p = j["paired"][key]["of1_scl1_bro1 - all off"];
    EXPECT_EQ(p["runs"], 2);
    EXPECT_EQ(p["scenes"], 1);
    EXPECT_NEAR(p["mean"].get<double>(), (d[0] + d[1]) / 2, 1e-12) << key;
    EXPECT_TRUE(p["ci95_half"].is_null()) << key;
    EXPECT_FALSE(j["paired"][key].contains("of added to the other two"));  // no middle rows were trained
  }
  // Different seeds train different models.
  EXPECT_NE(j["runs"][1]["run"]["results"]["instances/object"]["miou"],
            j["runs"][4]["run"]["results"]["instances/object"]["miou"]);
  const std::string md = read_file_text(tmp / "a" / "ablation.md");
  EXPECT_NE(md.find("## 3d-ovs/pixel (relevancy objects: hgs's object-embedding map, not in the paper)"),
            std::string::npos)
      << md;
  EXPECT_NE(md.find("## 3d-ovs/pixel-paper-map (the paper's language map"), std::string::npos) << md;
  EXPECT_NE(md.find("### 3d-ovs/pixel-paper-map (mIoU, paired by scene, seeds averaged within a scene; n = scenes)"),
            std::string::npos)
      << md;
  EXPECT_NE(md.find("| of1_scl1_bro1 - all off | "), std::string::npos) << md;
  EXPECT_NE(md.find(" | - | 1 | 2 |\n"), std::string::npos) << md;  // no interval, 1 scene, 2 runs
  EXPECT_NE(md.find(" ± "), std::string::npos);
  // Continuing: every run is on disk, so nothing is trained again and the summary is the same.
  r = test::run_hgs(cmd.substr(0, cmd.size() - 8));  // without --quiet: one line per run
  ASSERT_EQ(r.exit_code, 0) << r.err;
  size_t reused = 0;
  for (size_t p = r.out.find("(reused)"); p != std::string::npos; p = r.out.find("(reused)", p + 1)) ++reused;
  EXPECT_EQ(reused, 6u) << r.out;
  EXPECT_EQ(nlohmann::json::parse(read_file_text(tmp / "a" / "ablation.json"))["summary"], j["summary"]);
  // --reevaluate: the kept models evaluated again (here with another pixel relevancy), nothing trained: the object
  // figures and training times stay, the pixel figures are the new relevancy's. With --relevancy lerf pixel mode
  // is the paper's map: the figures the default run reported beside its own under pixel-paper-map, and no second.
  r = test::run_hgs(cmd.substr(0, cmd.size() - 8) + " --reevaluate --relevancy lerf");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  size_t again = 0;
  for (size_t p = r.out.find("evaluated again"); p != std::string::npos; p = r.out.find("evaluated again", p + 1))
    ++again;
  EXPECT_EQ(again, 6u) << r.out;
  const auto re = nlohmann::json::parse(read_file_text(tmp / "a" / "ablation.json"));
  ASSERT_EQ(re["runs"].size(), 6u);
  bool pixel_changed = false;
  for (size_t i = 0; i < 6; ++i) {
    const auto &a = j["runs"][i]["run"], &b = re["runs"][i]["run"];
    EXPECT_EQ(a["train_seconds"], b["train_seconds"]);
    EXPECT_EQ(a["results"]["instances/object"], b["results"]["instances/object"]);
    EXPECT_EQ(a["results"]["3d-ovs/object"], b["results"]["3d-ovs/object"]);
    pixel_changed |= a["results"]["instances/pixel"] != b["results"]["instances/pixel"];
    for (const std::string p : {"instances", "3d-ovs"}) {
      EXPECT_EQ(a["results"][p + "/pixel-paper-map"], b["results"][p + "/pixel"]) << p << " run " << i;
      EXPECT_FALSE(b["results"].contains(p + "/pixel-paper-map"));
    }
  }
  EXPECT_TRUE(pixel_changed);
  EXPECT_NE(read_file_text(tmp / "a" / "ablation.md").find("## 3d-ovs/pixel (relevancy lerf: the paper's language map"),
            std::string::npos);
  // The scoring variants on the kept models: their object mode is the base protocol's where only pixel mode's
  // windows change (instances-scaled), and every key is written.
  r = test::run_hgs("ablate " + s + " --out " + out +
                    " --iters 30 --rows ends --seeds 2 --protocol instances,instances-scaled,3d-ovs-labelled"
                    " --mode both --quiet --reevaluate");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto va = nlohmann::json::parse(read_file_text(tmp / "a" / "ablation.json"));
  for (const auto& run : va["runs"]) {
    const auto& res = run["run"]["results"];
    for (const char* key :
         {"instances-scaled/object", "instances-scaled/pixel", "3d-ovs-labelled/object", "3d-ovs-labelled/pixel"})
      ASSERT_TRUE(res.contains(key)) << key;
    EXPECT_EQ(res["instances-scaled/object"], res["instances/object"]);
  }
  // --anchor-support: the kept models evaluated with it say so in run.json, and are reused only with the same value.
  const std::string support =
      "ablate " + s + " --out " + out + " --iters 30 --rows ends --seeds 2 --protocol instances";
  r = test::run_hgs(support + " --anchor-support 0.01 --reevaluate --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const auto& run : nlohmann::json::parse(read_file_text(tmp / "a" / "ablation.json"))["runs"])
    EXPECT_FLOAT_EQ(run["run"].value("anchor_support", 0.f), 0.01f);
  // Each run's report names it beside its object-mode figures.
  const auto rep = nlohmann::json::parse(read_file_text(tmp / "a" / "s" / "seed0" / "of0_scl0_bro0" / "report.json"));
  EXPECT_EQ(rep["reports"][0]["mode"], "object");
  EXPECT_EQ(rep["reports"][0]["extra"].value("anchor_support", 0.0), 0.01);
  auto count = [](const std::string& out, const std::string& what) {
    size_t n = 0;
    for (size_t p = out.find(what); p != std::string::npos; p = out.find(what, p + 1)) ++n;
    return n;
  };
  r = test::run_hgs(support + " --anchor-support 0.01");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(count(r.out, "(reused)"), 4u) << r.out;
  r = test::run_hgs(support + " --anchor-support 0.02");  // other figures: trained and evaluated again
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(count(r.out, "(reused)"), 0u) << r.out;
  // --rows single: the three rows with one component on, nothing else (with leave-one-out, the 8 rows).
  r = test::run_hgs("ablate " + s + " --out " + (tmp / "single").string() +
                    " --iters 5 --rows single --protocol instances --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto sj = nlohmann::json::parse(read_file_text(tmp / "single" / "ablation.json"));
  ASSERT_EQ(sj["summary"].size(), 3u);
  EXPECT_EQ(sj["summary"][0]["row"], "of1_scl0_bro0");
  EXPECT_EQ(sj["summary"][1]["row"], "of0_scl1_bro0");
  EXPECT_EQ(sj["summary"][2]["row"], "of0_scl0_bro1");
  r = test::run_hgs("ablate " + s + " --out " + (tmp / "c").string() + " --iters 5 --protocol instances,bogus --quiet");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("unknown protocol 'bogus' (one of instances, instances-scaled"), std::string::npos) << r.err;
  // A protocol without labels is a clear error before any training.
  fs::remove_all(tmp / "s" / "segmentations");
  r = test::run_hgs("ablate " + s + " --out " + (tmp / "b").string() + " --iters 5 --protocol 3d-ovs --quiet");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("no labels for the 3d-ovs protocol"), std::string::npos) << r.err;
  EXPECT_FALSE(fs::exists(tmp / "b" / "ablation.json"));
}
