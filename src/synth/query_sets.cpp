// The realistic world's phrases and query sets (query_sets.h): embeddings from the lexicon (language.h), query
// sets kept to the phrases whose answer in the scene is one object.
#include "synth/query_sets.h"

#include <cmath>
#include <map>

#include "scene/text_embeddings.h"
#include "synth/language.h"

namespace hgs::synth {
nlohmann::json float_array(const std::vector<float>& v) {
  nlohmann::json a = nlohmann::json::array();
  for (float x : v) a.push_back(std::round(double(x) * 1e6) / 1e6);
  return a;
}

namespace {

// Whether "the <a> one" could also mean a thing of colour b: the same colour or one family ("lime", "green").
bool colours_collide(const std::string& a, const std::string& b) {
  auto family = [](const std::string& c) {
    const std::string f = colour_family(c);
    return f.empty() ? c : f;
  };
  return !a.empty() && !b.empty() && family(a) == family(b);
}

}  // namespace

void realistic_text(const World& world, const std::vector<std::string>& surfaces,
                    const std::vector<std::string>& distractors, int dim, nlohmann::json& text,
                    nlohmann::json& queries) {
  text = nlohmann::json::object();
  queries = nlohmann::json::object();
  for (const auto& set : query_set_names()) queries[set] = nlohmann::json::object();
  std::vector<Lexeme> things;  // the objects, then the surfaces
  for (const auto& o : world.objects) things.push_back(lexeme_of(o.name));
  for (const auto& s : surfaces) things.push_back(lexeme_of(s));
  for (size_t i = 0; i < world.objects.size(); ++i) {
    const auto& o = world.objects[i];
    const Lexeme& x = things[i];
    text[o.name] = float_array(text_embedding(x, dim));
    queries["names"][o.name] = o.id;
    const std::string syn = synonym_of(o.name);
    if (!syn.empty()) {
      text[syn] = float_array(text_embedding({"", x.noun, x.category, x.group}, dim, syn));
      queries["synonyms"][syn] = o.id;
    }
    int same_group = 0, same_category = 0, same_colour = 0;
    for (const Lexeme& y : things) {
      same_group += y.group == x.group;
      same_category += y.category == x.category;
      same_colour += colours_collide(y.attribute, x.attribute);
    }
    text[x.category] = float_array(text_embedding({"", "", x.category, x.group}, dim));
    text[x.group] = float_array(text_embedding({"", "", "", x.group}, dim));
    if (same_group == 1) queries["hypernyms"][x.group] = o.id;
    else if (same_category == 1) queries["hypernyms"][x.category] = o.id;
    const std::string attr = attribute_phrase(x);
    if (!attr.empty()) {
      text[attr] = float_array(text_embedding({x.attribute, "", "", ""}, dim, "one"));
      if (same_colour == 1) queries["attributes"][attr] = o.id;
    }
  }
  for (const auto& s : surfaces) text[s] = float_array(text_embedding(lexeme_of(s), dim));
  for (const auto& d : distractors) {
    text[d] = float_array(in_lexicon(d) ? text_embedding(lexeme_of(d), dim) : generic_text_embedding(d, dim));
  }
  for (const char* c : kCanonicalPhrases) text[c] = float_array(generic_text_embedding(c, dim));
}

}  // namespace hgs::synth
