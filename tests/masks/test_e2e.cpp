// End to end through the `hgs` binary: synth --mask-style sam / --mask-ids per-view, `hgs masks import` of
// the SAM JSON it writes, and a LangSplat-format fixture (made here from a synthetic scene) that imports, trains
// and evaluates with the LERF-OVS protocol.
#include <gtest/gtest.h>

#include <map>
#include <nlohmann/json.hpp>

#include "core/fs.h"
#include "core/image.h"
#include "core/npy.h"
#include "masks_test_util.h"
#include "scene/scene.h"
#include "test_util.h"

using namespace hgs;
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

const std::string kTiny =
    "--views 6 --width 64 --height 48 --objects 4 --points 400 --feature-dim 8 --supersample 1 --quiet --threads 2";

void synth(const fs::path& out, const std::string& extra) {
  auto r = test::run_hgs("synth --world simple --out " + out.string() + " " + kTiny + " " + extra);
  ASSERT_EQ(r.exit_code, 0) << r.err;
}

std::vector<std::string> stems(const fs::path& scene) {
  std::vector<std::string> s;
  for (auto& e : fs::directory_iterator(scene / "images")) s.push_back(e.path().stem().string());
  std::sort(s.begin(), s.end());
  return s;
}

}  // namespace

TEST(MasksCli, HelpIsClear) {
  auto r = test::run_hgs("--help");
  EXPECT_NE(r.out.find("(subcommands: generate, click, import, associate, score)"), std::string::npos) << r.out;
  r = test::run_hgs("masks --help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* s : {"generate", "click", "import", "associate", "score"})
    EXPECT_NE(r.out.find(s), std::string::npos) << s;
  r = test::run_hgs("masks import --help");
  EXPECT_EQ(r.exit_code, 0);
  for (const char* s : {"sam-json", "sam-png", "sam2-png", "langsplat", "--level", "--force", "smallest"})
    EXPECT_NE(r.out.find(s), std::string::npos) << s;
  r = test::run_hgs("masks");
  EXPECT_NE(r.exit_code, 0);
}

TEST(MasksCli, SynthSamPerViewImportsToTheSynthMasksAndTheTruth) {
  test::TempDir t;
  const fs::path s = t / "s";
  synth(s, "--noise none --mask-style sam --mask-ids per-view");
  EXPECT_FALSE(fs::exists(s / "masks" / "objects.json"));
  std::map<std::string, std::vector<uint8_t>> before;
  for (auto& st : stems(s)) before[st] = read_file_bytes(s / "masks" / (st + ".png"));
  auto r = test::run_hgs("masks import " + s.string() + " --from sam-json " + (s / "sam").string() + " --quiet");
  EXPECT_NE(r.exit_code, 0);  // masks/ exists: needs --force
  EXPECT_NE(r.err.find("--force"), std::string::npos) << r.err;
  r = test::run_hgs("masks import " + s.string() + " --from sam-json " + (s / "sam").string() + " --force --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("imported 6 of 6 views"), std::string::npos) << r.out;
  const json truth = json::parse(read_file_text(s / "gt" / "mask_ids.json"));
  size_t labelled = 0, object_px = 0, covered = 0;
  for (auto& st : stems(s)) {
    // Per-view ids are the position in the view's SAM list, so the import gives the synth's label map exactly.
    EXPECT_EQ(read_file_bytes(s / "masks" / (st + ".png")), before[st]) << st;
    LabelMap m = load_label_png(s / "masks" / (st + ".png"));
    LabelMap gt = load_label_png(s / "gt" / "instances" / (st + ".png"));
    for (size_t p = 0; p < m.v.size(); ++p) {
      object_px += gt.v[p] != 0;
      if (!m.v[p]) continue;
      ++labelled;
      const json& e = truth[st][std::to_string(m.v[p])];
      ASSERT_EQ(e["object"].get<int>(), gt.v[p]) << st << " pixel " << p;  // no noise: every mask is exact
      covered += gt.v[p] != 0;
    }
  }
  EXPECT_GT(labelled, 0u);
  EXPECT_GE(covered, object_px * 95 / 100);  // objects under 16 px are dropped as SAM drops them
  // import.json's part_of recovers the whole / half hierarchy that flattening hides.
  const json meta = json::parse(read_file_text(s / "masks" / "import.json"));
  int halves = 0;
  for (auto& st : stems(s))
    for (auto& m : meta["views"][st]["masks"]) {
      const json& e = truth[st][std::to_string(m["id"].get<int>())];
      if (!e.contains("part")) continue;
      ++halves;
      ASSERT_FALSE(m["part_of"].is_null()) << st << " mask " << m["id"];
      const json& whole = truth[st][std::to_string(m["part_of"].get<int>())];
      EXPECT_EQ(whole["entity"], e["object"]) << st << " mask " << m["id"];
    }
  EXPECT_GT(halves, 0);
}

TEST(MasksCli, SynthSamConsistentMatchesUpToAPerViewPermutation) {
  test::TempDir t;
  const fs::path s = t / "s";
  synth(s, "--noise medium --mask-style sam");
  json names = json::parse(read_file_text(s / "masks" / "objects.json"));
  EXPECT_GT(names.size(), 4u);  // objects, halves and background surfaces are named
  std::map<std::string, LabelMap> synth_masks;
  for (auto& st : stems(s)) synth_masks[st] = load_label_png(s / "masks" / (st + ".png"));
  auto r =
      test::run_hgs("masks import " + s.string() + " --from sam-json " + (s / "sam").string() + " --force --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (auto& [st, want] : synth_masks) {
    LabelMap got = load_label_png(s / "masks" / (st + ".png"));
    ASSERT_EQ(got.v.size(), want.v.size());
    std::map<int, int> fwd, back;
    for (size_t p = 0; p < got.v.size(); ++p) {
      auto [i1, n1] = fwd.emplace(got.v[p], want.v[p]);
      auto [i2, n2] = back.emplace(want.v[p], got.v[p]);
      ASSERT_EQ(i1->second, want.v[p]) << st << ": imported id " << got.v[p] << " maps to two synth ids";
      ASSERT_EQ(i2->second, got.v[p]) << st << ": synth id " << want.v[p] << " maps to two imported ids";
    }
    EXPECT_EQ(fwd[0], 0);
  }
  EXPECT_FALSE(fs::exists(s / "masks" / "objects.json"));  // the import cannot name per-view ids
}

TEST(MasksCli, SynthPerViewLabelIdsMapBackToTheConsistentMasks) {
  test::TempDir t;
  synth(t / "a", "--seed 3 --objects-only");  // the objects' ids (a surface's per-view truth is object 0)
  synth(t / "b", "--seed 3 --objects-only --mask-ids per-view");
  const json truth = json::parse(read_file_text(t / "b" / "gt" / "mask_ids.json"));
  EXPECT_FALSE(fs::exists(t / "b" / "masks" / "objects.json"));
  bool some_differ = false;
  for (auto& st : stems(t / "a")) {
    LabelMap a = load_label_png(t / "a" / "masks" / (st + ".png")),
             b = load_label_png(t / "b" / "masks" / (st + ".png"));
    some_differ |= a.v != b.v;
    for (size_t p = 0; p < a.v.size(); ++p)
      ASSERT_EQ(b.v[p] ? truth[st][std::to_string(b.v[p])]["object"].get<int>() : 0, a.v[p]) << st;
    EXPECT_EQ(read_file_bytes(t / "a" / "images" / (st + ".png")), read_file_bytes(t / "b" / "images" / (st + ".png")));
  }
  EXPECT_TRUE(some_differ);
}

// LangSplat fixture: from a synthetic scene's exact instance maps, the four levels LangSplat writes (here the same
// masks at every level, indices offset by the earlier levels' counts as preprocess.py does) and one feature per
// mask (the text embedding of its object's name), float32 as LangSplat saves them.
TEST(MasksCli, LangSplatFixtureImportsTrainsAndEvaluates) {
  test::TempDir t;
  const fs::path s = t / "s", ls = t / "language_features";
  synth(s, "--noise none");
  const json te = json::parse(read_file_text(s / "text_embeddings.json"));
  const json names = json::parse(read_file_text(s / "masks" / "objects.json"));
  for (auto& st : stems(s)) {
    LabelMap gt = load_label_png(s / "gt" / "instances" / (st + ".png"));
    std::vector<int> present;
    for (int k = 1; k <= 4; ++k)
      if (std::count(gt.v.begin(), gt.v.end(), uint16_t(k))) present.push_back(k);
    const size_t n = present.size(), hw = gt.v.size(), D = 8;
    std::vector<float> seg(4 * hw, -1.f), feat;
    for (int level = 0; level < 4; ++level) {
      for (size_t i = 0; i < n; ++i) {
        auto e = te[names[std::to_string(present[i])].get<std::string>()].get<std::vector<float>>();
        feat.insert(feat.end(), e.begin(), e.end());
        for (size_t p = 0; p < hw; ++p)
          if (gt.v[p] == present[i]) seg[level * hw + p] = float(level * n + i);
      }
    }
    test::write_f32(ls / (st + "_s.npy"), {4, size_t(gt.height), size_t(gt.width)}, seg);
    test::write_f32(ls / (st + "_f.npy"), {4 * n, D}, feat);
  }
  auto r = test::run_hgs("masks import " + s.string() + " --from langsplat " + ls.string() +
                         " --level l --feature-stride 4 --force --quiet");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  Scene sc = load_scene(s);
  ASSERT_TRUE(sc.load_mask(0));
  int gh, gw, d;
  auto grid = sc.load_feature_grid(0, gh, gw, d);
  ASSERT_TRUE(grid);
  EXPECT_EQ(d, 8);
  EXPECT_EQ(gw, 16);
  EXPECT_EQ(gh, 12);
  r = test::run_hgs("train " + s.string() + " --out " + (t / "m").string() + " --iters 40 --quiet --threads 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = test::run_hgs("eval " + s.string() + " " + (t / "m").string() + " --protocol lerf-ovs --out " +
                    (t / "r" / "report.json").string() + " --no-png --quiet --threads 2");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(fs::exists(t / "r" / "report.json"));
}
