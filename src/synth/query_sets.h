// The realistic world's text side: simulated CLIP text embeddings (language.h) of every phrase a scene's
// evaluation or a user may ask, and the named query sets of gt/queries.json that `hgs eval --queries` reads:
//   names      every object's class name ("red mug")
//   synonyms   another noun of the same category, no colour ("coffee cup")
//   hypernyms  the coarse group ("kitchenware") where exactly one thing of the scene (objects and surfaces) is in
//              it, else the category ("cup") where exactly one thing is one
//   attributes "the red one", only where no other thing of the scene has that colour, or one of its family
// Each set maps a phrase to the object id of gt/instances it asks for.
#pragma once
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "synth/world.h"

namespace hgs::synth {

// text: phrase -> [dim] embedding (JSON arrays of floats); queries: {set: {phrase: object id}}.
// surfaces: the scene's background surface names; distractors: phrases of nothing in the scene (pool names not
// placed and unrelated phrases).
void realistic_text(const World& world, const std::vector<std::string>& surfaces,
                    const std::vector<std::string>& distractors, int dim, nlohmann::json& text,
                    nlohmann::json& queries);

// A text embedding as text_embeddings.json of `hgs synth` holds it: a JSON array, each float to 6 decimals.
nlohmann::json float_array(const std::vector<float>& v);

// The query set names, in order.
inline const std::vector<std::string>& query_set_names() {
  static const std::vector<std::string> n = {"names", "synonyms", "hypernyms", "attributes"};
  return n;
}

}  // namespace hgs::synth
