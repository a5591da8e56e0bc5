// Where the instances protocol takes the true objects' names from: gt/objects.json (written by `hgs synth`), so a
// scene whose training masks were renamed (as `hgs masks associate` does) still evaluates against the truth, and
// masks/objects.json for a scene without gt/objects.json (a real capture), which the report's extra says.
#include <gtest/gtest.h>

#include <map>
#include <nlohmann/json.hpp>
#include <set>

#include "core/error.h"
#include "core/fs.h"
#include "eval/instances.h"
#include "eval/run.h"
#include "expect_error.h"
#include "scene/scene.h"
#include "synth/synth.h"
#include "synth_options.h"
#include "test_util.h"

using namespace hgs;
using namespace hgs::eval;
namespace fs = std::filesystem;
using json = nlohmann::json;

namespace {

// A small scene (test views 0 and 8) and the truth's id -> name from synth.json.
std::map<int, std::string> small_scene(const fs::path& dir) {
  synth::generate(dir, test::SmallSynth().views(9).objects(3).points(300).feature_dim(8).noise("none"));
  std::map<int, std::string> truth;
  const json meta = json::parse(read_file_text(dir / "synth.json"));
  for (auto& e : meta["objects"]) truth[e["id"].get<int>()] = e["name"].get<std::string>();
  return truth;
}

// The instances protocol with a perfect predictor: the gt/instances mask of the object that `truth` names so.
EvalReport evaluate(const fs::path& dir, const std::map<int, std::string>& truth) {
  const Scene scene = load_scene(dir);
  MaskFn oracle = [&](int view, const std::string& q, std::vector<float>*) {
    InstanceLabels I = load_instance_masks(dir, scene.views[view].name, truth);
    for (size_t k = 0; k < I.names.size(); ++k)
      if (I.names[k] == q) return I.masks[k];
    return Mask(I.masks[0].size(), 0);
  };
  RunOptions opt;
  opt.progress = false;
  return run_instances(scene, oracle, opt);
}

std::set<std::string> queries(const EvalReport& r) {
  std::set<std::string> q;
  for (auto& rec : r.records) q.insert(rec.query);
  return q;
}

}  // namespace

TEST(EvalInstanceNames, TruthComesFromGtObjectsJsonWhateverTheMasksSay) {
  test::TempDir tmp;
  const fs::path dir = tmp / "s";
  const std::map<int, std::string> truth = small_scene(dir);
  EXPECT_EQ(json::parse(read_file_text(dir / "gt" / "objects.json")),
            json(json::parse(read_file_text(dir / "masks" / "objects.json"))));
  // The training masks' names rewritten as association writes them: other ids, generic names.
  atomic_write_text(dir / "masks" / "objects.json", R"({"1": "object 1", "2": "object 2", "5": "object 3"})");
  const EvalReport r = evaluate(dir, truth);
  ASSERT_FALSE(r.records.empty());
  EXPECT_EQ(r.extra["object_names"], "gt/objects.json");
  std::set<std::string> names;
  for (auto& [id, name] : truth) names.insert(name);
  EXPECT_EQ(queries(r), names);  // every object is seen in a test view of this scene
  for (auto& rec : r.records) EXPECT_EQ(rec.iou, 1.0) << rec.frame << " " << rec.query;
}

TEST(EvalInstanceNames, SceneWithoutGtObjectsJsonFallsBackToMasksObjectsJson) {
  test::TempDir tmp;
  const fs::path dir = tmp / "s";
  const std::map<int, std::string> truth = small_scene(dir);
  fs::remove(dir / "gt" / "objects.json");
  EXPECT_EQ(object_names_file(dir), dir / "masks" / "objects.json");
  // masks/objects.json names the ids of gt/instances (a real capture's layout): its names are the queries.
  atomic_write_text(dir / "masks" / "objects.json", R"({"1": "left thing", "2": "middle thing", "3": "right thing"})");
  const std::map<int, std::string> renamed = {{1, "left thing"}, {2, "middle thing"}, {3, "right thing"}};
  EXPECT_EQ(load_object_names(dir), renamed);
  const EvalReport r = evaluate(dir, renamed);
  ASSERT_FALSE(r.records.empty());
  EXPECT_EQ(r.extra["object_names"], "masks/objects.json");
  EXPECT_EQ(queries(r), (std::set<std::string>{"left thing", "middle thing", "right thing"}));
  for (auto& rec : r.records) EXPECT_EQ(rec.iou, 1.0) << rec.frame << " " << rec.query;
  // Neither file: the error names both.
  fs::remove(dir / "masks" / "objects.json");
  try {
    load_object_names(dir);
    FAIL() << "no error without any objects.json";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find((dir / "masks" / "objects.json").string() + ": file not found"), std::string::npos) << what;
    EXPECT_NE(what.find((dir / "gt" / "objects.json").string()), std::string::npos) << what;
  }
}

TEST(EvalInstanceNames, ErrorsNameGtObjectsJson) {
  test::TempDir tmp;
  const fs::path f = tmp / "s" / "gt" / "objects.json";
  fs::create_directories(f.parent_path());
  fs::create_directories(tmp / "s" / "masks");
  atomic_write_text(tmp / "s" / "masks" / "objects.json", R"({"1": "mug"})");  // valid, but not read
  atomic_write_text(f, R"({"x": "mug"})");
  try {
    load_object_names(tmp / "s");
    FAIL() << "no error for a malformed gt/objects.json";
  } catch (const Error& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find(f.string() + ": key \"x\" is not an object id"), std::string::npos) << what;
  }
}

TEST(EvalInstanceNames, AQuerySetAsksItsPhrasesOfTheirObjects) {
  // --queries synonyms: every phrase of the set asked in every test view that shows its object, scored against
  // that object; a perfect predictor of the phrases' objects scores 1.
  test::TempDir tmp;
  const fs::path dir = tmp / "r";
  synth::generate(dir, test::SmallSynth().realistic().views(9).objects(3).points(300).feature_dim(8).noise("none"));
  const json sets = json::parse(read_file_text(dir / "gt" / "queries.json"));
  const std::map<int, std::string> names = load_object_names(dir);
  const Scene scene = load_scene(dir);
  std::map<std::string, int> object_of;
  for (auto& [phrase, id] : sets["synonyms"].items()) object_of[phrase] = id.get<int>();
  MaskFn oracle = [&](int view, const std::string& q, std::vector<float>*) {
    InstanceLabels I = load_instance_masks(dir, scene.views[view].name, names);
    for (size_t k = 0; k < I.ids.size(); ++k)
      if (object_of.count(q) && I.ids[k] == object_of.at(q)) return I.masks[k];
    return Mask(I.masks[0].size(), 0);
  };
  RunOptions opt;
  opt.progress = false;
  opt.query_set = "synonyms";
  const EvalReport r = run_instances(scene, oracle, opt);
  ASSERT_FALSE(r.records.empty());
  EXPECT_EQ(r.extra["query_set"], "synonyms");
  for (auto& rec : r.records) {
    EXPECT_TRUE(object_of.count(rec.query)) << rec.query;
    EXPECT_DOUBLE_EQ(rec.iou, 1.0) << rec.query;
  }
  opt.query_set = "adjectives";
  EXPECT_FILE_ERROR(run_instances(scene, oracle, opt), dir / "gt" / "queries.json",
                    "no query set 'adjectives' (it has: attributes, ");
}
