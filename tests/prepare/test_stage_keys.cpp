// The stage keys of `hgs prepare` (stage_options.h), without running any stage: changing any option of a stage
// changes the key of that stage and of every stage downstream of it, and no other. The options are walked as
// JSON, so a field added to a stage's options is covered here as soon as its JSON holds it.
#include <gtest/gtest.h>

#include <map>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "prepare/prepare.h"
#include "prepare/stage_options.h"

namespace hgs::prepare {
namespace {
using json = nlohmann::json;

// `stage` and every stage that reads its outputs, directly or through others.
std::set<std::string> downstream(const std::string& stage) {
  std::set<std::string> out{stage};
  for (bool grew = true; grew;) {
    grew = false;
    for (const auto& [name, inputs] : stage_inputs())
      for (const std::string& in : inputs)
        if (out.count(in) && out.insert(name).second) grew = true;
  }
  return out;
}

// JSON pointers to the leaves of `j` (numbers, booleans, strings, arrays), through nested objects.
void leaves(const json& j, const json::json_pointer& at, std::vector<json::json_pointer>& out) {
  if (!j.is_object()) {
    out.push_back(at);
    return;
  }
  for (const auto& [k, v] : j.items()) leaves(v, at / k, out);
}

// Another value of the same type.
json changed(const json& v) {
  if (v.is_boolean()) return !v.get<bool>();
  if (v.is_number_integer()) return v.get<long>() + 1;
  if (v.is_number()) return v.get<double>() + 0.5;
  if (v.is_string()) return v.get<std::string>() + "x";
  if (v.is_array()) {
    json a = v;
    a.push_back(v.empty() ? json("x") : v.back());
    return a;
  }
  ADD_FAILURE() << "no change for " << v.dump();
  return v;
}

StageOptions example_options() {
  StageOptions o;
  o.features = {"SIMPLE_RADIAL", 4096};
  o.matching = {"exhaustive", ""};
  o.sam.model = "sam.safetensors:1000:1 f32 0 0";
  o.depth.iters = 1000;
  o.clip.model = "clip.safetensors:2000:2 f32";
  o.text = {o.clip.model, {"red mug", "object", "things", "stuff", "texture"}};
  return o;
}

TEST(PrepareStageKeys, EveryOptionRerunsItsStageAndTheStagesDownstreamOnly) {
  const StageOptions base = example_options();
  const json j0 = base;
  const std::map<std::string, std::string> keys0 = stage_keys(base, "input key");
  ASSERT_EQ(keys0.size(), stage_inputs().size() + 1);
  std::set<std::string> keys_seen;
  for (const auto& [name, key] : keys0) keys_seen.insert(key);
  EXPECT_EQ(keys_seen.size(), keys0.size()) << "two stages share a key";
  int options = 0;
  for (const auto& [stage, inputs] : stage_inputs()) {
    std::vector<json::json_pointer> fields;
    if (!j0.at(stage).empty()) leaves(j0.at(stage), json::json_pointer("/" + stage), fields);
    const std::set<std::string> rerun = downstream(stage);
    for (const json::json_pointer& f : fields) {
      json j = j0;
      j[f] = changed(j0[f]);
      const StageOptions o = j.get<StageOptions>();
      // The change survives the struct (from_json and to_json agree on the field).
      EXPECT_NE(json(o)[f], j0[f]) << f.to_string();
      const std::map<std::string, std::string> keys = stage_keys(o, "input key");
      for (const auto& [name, key] : keys0) {
        if (rerun.count(name)) EXPECT_NE(keys.at(name), key) << f.to_string() << " left stage " << name << " as it was";
        else EXPECT_EQ(keys.at(name), key) << f.to_string() << " reran stage " << name;
      }
      ++options;
    }
  }
  // At least the fields of today: features 2, matching 2, sam 1 + 7, depth 1, associate 15, clip 1 + 4, text 2.
  EXPECT_GE(options, 35);
  // The input reruns everything but the text embeddings, which read no image.
  const std::map<std::string, std::string> keys = stage_keys(base, "other input key");
  for (const auto& [name, key] : keys0) {
    if (name == "text") EXPECT_EQ(keys.at(name), key);
    else EXPECT_NE(keys.at(name), key) << name;
  }
}

TEST(PrepareStageKeys, TheStageGraphIsInOrderAndReadsOnlyEarlierStages) {
  std::set<std::string> before{"input"};
  for (const auto& [name, inputs] : stage_inputs()) {
    for (const std::string& in : inputs) EXPECT_TRUE(before.count(in)) << name << " reads " << in;
    EXPECT_TRUE(before.insert(name).second) << name << " twice";
  }
  std::vector<std::string> names{"input"}, grouped;
  for (const auto& [name, inputs] : stage_inputs()) names.push_back(name);
  for (const auto& [name, group] : stage_groups()) grouped.push_back(name);
  EXPECT_EQ(names, grouped) << "stage_groups (prepare.h) and stage_inputs list other stages";
  EXPECT_EQ(downstream("depth"), (std::set<std::string>{"depth", "associate"}));
  EXPECT_EQ(downstream("undistort"),
            (std::set<std::string>{"undistort", "sam", "import", "depth", "associate", "clip"}));
}

}  // namespace
}  // namespace hgs::prepare
